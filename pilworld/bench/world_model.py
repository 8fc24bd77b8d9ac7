"""``pilworld bench world-model``: single-step image quality of a world model on held-out episodes, and its speed.

**Held-out data** (:func:`heldout_dataset`): whole runs of the best scripted checkpoint and of a
weaker one (so failures are represented too) on every task, collected with seeds from
:data:`HELDOUT_SEED0` = 1,000,000 on — the training set used seeds 0–19 (``pilworld sim collect
--episodes 20``, docs/sim_rig.md), so no layout or policy error draw is shared with training. The
videos are stored ``lossless``: the targets are the rendered frames themselves, not codec output. The
set is cached under ``$PILWORLD_CACHE/heldout/<key of the arguments>`` and reused once complete.

**Single-step protocol** (the paper's): for every clip of the held-out set (or a seeded subset), the
model gets the real current and history frames of every view and the control video Γ drawn from the
clip's ground-truth stride-aligned actions, predicts K frames, and is scored against the true future
frames: PSNR / SSIM (/ LPIPS) overall, per view and per frame index (see
:mod:`pilworld.world_model.metrics` for the exact definitions). The copy-the-current-frame baseline
(:class:`~pilworld.world_model.base.FrozenWorldModel`) is scored on the same clips; ``gain_over_frozen_db``
is the PSNR difference per view. An optional second model (the no-history ablation) is scored the same way.

Caveat of simulated data: a camera that does not move between frames (an idle arm's wrist view) renders
bit-identical frames, which the frozen baseline reproduces exactly and which then score the 100 dB PSNR
cap (about 28% of the images with the default held-out set). ``exact_frozen`` reports that share, and
``psnr_pooled`` / ``gain_over_frozen_pooled_db`` (PSNR of the mean MSE) compare without the cap's weight.

**Resolution**: when the model's ``info.height × info.width`` differs from the dataset's images, the
current, history and future frames are area-resized to the model's size (``batching.resize_images``)
and Γ is drawn directly at that size, so every figure is at the model's resolution.

**Latency**: the median and 90th percentile over ``repeats`` single-sample ``model.predict`` calls
(K frames × all views, after 2 warm-up calls); ``realtime_factor`` = robot time covered by one chunk
(K·Δ control steps at the rig's control rate) / latency, so ≥ 1 means imagination keeps pace.
"""

from __future__ import annotations

import argparse
import hashlib
import json
import time
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np
import torch
from tqdm import tqdm

from pilworld.bench.common import machine_info
from pilworld.bench.flags import add_json, add_rig
from pilworld.bench.output import Column, emit, num, table
from pilworld.config.rig import RigConfig
from pilworld.data.clip_dataset import ClipDataset, default_cache_dir
from pilworld.data.clips import ClipSpec
from pilworld.data.reader import EpisodeStore
from pilworld.io.atomic import write_json
from pilworld.options.parse import parse_names
from pilworld.world_model.base import (
    FrozenWorldModel,
    HistoryAblation,
    PredictRequest,
    WorldModel,
    WorldModelBatch,
    WorldModelInfo,
)
from pilworld.world_model.batching import collate_clips, control_renderer, resize_images
from pilworld.world_model.metrics import SingleStepScores, load_lpips
from simrig.files import SIM_RIG

CONTROL_STRIDE = 3  # Δ in control steps (paper)
TRAINING_SEEDS = range(0, 20)  # seeds of the world-model training set (docs/sim_rig.md)
HELDOUT_SEED0 = 1_000_000
# The best checkpoint plus one that fails about half its subtasks (docs/sim_rig.md success table),
# so held-out clips show failures too; a run costs ~1–3 s, so the second checkpoint is cheap.
WEAK_CHECKPOINT = "scripted_step_05k"
HELDOUT_VIDEO_MODE = "lossless"
WARMUP_CALLS = 2
_DIGITS = 4


# ---------------------------------------------------------------------- held-out data


def heldout_checkpoints() -> tuple[str, ...]:
    from pilworld.policies.scripted import BEST_CHECKPOINT

    return (BEST_CHECKPOINT, WEAK_CHECKPOINT)


def heldout_dataset(
    rig_path: str | Path,
    *,
    tasks: Sequence[str],
    episodes: int,
    seed0: int = HELDOUT_SEED0,
    checkpoints: Sequence[str] | None = None,
    cache_dir: str | Path | None = None,
    workers: int | None = None,
    progress: bool = True,
) -> Path:
    """Collect (or reuse) the held-out runs and return the dataset root.

    ``episodes`` runs per task × checkpoint with seeds ``seed0 … seed0 + episodes − 1``; a seed of
    the training set (:data:`TRAINING_SEEDS`) is refused. The folder is keyed by the rig file's
    content and every argument; ``heldout.json`` beside the dataset marks it complete (written only
    after :func:`~pilworld.collection.collect.collect` returned), and an incomplete folder is resumed.
    """
    from pilworld.collection.collect import collect
    from pilworld.types import ChunkSpec

    if isinstance(episodes, bool) or not isinstance(episodes, int) or episodes < 1:
        raise ValueError(f"episodes: expected an integer >= 1, got {episodes!r}")
    if not tasks:
        raise ValueError("tasks: expected at least one task")
    seeds = list(range(seed0, seed0 + episodes))
    reused = sorted(set(seeds) & set(TRAINING_SEEDS))
    if reused:
        raise ValueError(
            f"seed0: seeds {reused} were used for the training set (seeds "
            f"{TRAINING_SEEDS.start}–{TRAINING_SEEDS.stop - 1}); choose seeds outside it"
        )
    ckpts = list(checkpoints or heldout_checkpoints())
    rig = Path(rig_path)
    spec = ChunkSpec()
    key_fields = {
        "rig_sha1": hashlib.sha1(rig.read_bytes()).hexdigest(),  # FileNotFoundError names a missing rig
        "tasks": list(tasks),
        "checkpoints": ckpts,
        "episodes": episodes,
        "seed0": seed0,
        "video_mode": HELDOUT_VIDEO_MODE,
        "chunk_spec": repr(spec),
    }
    key = hashlib.sha1(json.dumps(key_fields, sort_keys=True).encode()).hexdigest()[:16]
    folder = Path(cache_dir or default_cache_dir()) / "heldout" / key
    root, marker = folder / "dataset", folder / "heldout.json"
    if marker.is_file():
        return root
    summary = collect(
        root,
        rig_path=str(rig),
        tasks=list(tasks),
        checkpoints=ckpts,
        episodes=episodes,
        seed0=seed0,
        workers=workers,
        video_mode=HELDOUT_VIDEO_MODE,
        spec=spec,
        progress=progress,
    )
    write_json(marker, {**key_fields, "rig": str(rig.resolve()), "seeds": seeds, "collect": summary})
    return root


def heldout_description(root: Path) -> dict[str, Any]:
    """What the JSON says about the held-out set: where, how much, which seeds, and their training overlap."""
    store = EpisodeStore(root)
    seeds = sorted({int(e["seed"]) for e in store.episodes})
    tasks: set[str] = set()
    for e in store.episodes:
        raw = e.get("extra")
        if raw:
            extra = json.loads(raw)
            tasks.add(str(extra.get("task") or extra.get("sim_task") or "?"))
    overlap = sorted(set(seeds) & set(TRAINING_SEEDS))
    out: dict[str, Any] = {
        "root": str(root),
        "episodes": store.num_episodes,
        "frames": store.num_frames,
        "tasks": sorted(tasks),
        "checkpoints": sorted({str(e.get("checkpoint", "")) for e in store.episodes}),
        "seeds": seeds,
        "training_seeds": [TRAINING_SEEDS.start, TRAINING_SEEDS.stop - 1],
        "seeds_used_in_training": bool(overlap),
        "video_mode": store.spec.video_mode,
    }
    marker = root.parent / "heldout.json"
    if marker.is_file():
        collected = json.loads(marker.read_text(encoding="utf-8")).get("collect", {})
        out["success"], out["failure"] = collected.get("success"), collected.get("failure")
    return out


# ---------------------------------------------------------------------- batches at a model's shape


def fit_batch(batch: WorldModelBatch, info: WorldModelInfo, what: str = "model") -> WorldModelBatch:
    """``batch`` (views in ``info.views`` order, K = ``info.future``) brought to ``info``'s size and H_h.

    Images are area-resized; a model with fewer history frames gets the most recent ones. The ground
    truth is dropped (a model never sees it).
    """
    n_views, n_future = batch.current.shape[1], batch.control.shape[1]
    if n_views != len(info.views):
        raise ValueError(f"{what}: expects {len(info.views)} views {list(info.views)}, the clips have {n_views}")
    if n_future != info.future:
        raise ValueError(f"{what}: predicts K={info.future} frames, the clips have K={n_future}")
    have = batch.history.shape[2]
    history, valid = (
        batch.history[:, :, max(0, have - info.history) :],
        batch.history_valid[:, max(0, have - info.history) :],
    )
    if info.history > have:
        # A model with a longer memory than the clips: pad at the front with copies flagged invalid, the rule
        # the imagined branch's memory uses at a rollout's start.
        pad = info.history - have
        first = batch.history[:, :, :1] if have else batch.current[:, :, None]
        history = torch.cat([first.expand(-1, -1, pad, -1, -1, -1), history], 2)
        valid = torch.cat([torch.zeros(valid.shape[0], pad, dtype=torch.bool), valid], 1)
    h, w = info.height, info.width
    return WorldModelBatch(
        current=resize_images(batch.current, h, w),
        history=resize_images(history, h, w),
        history_valid=valid,
        control=resize_images(batch.control, h, w),
        actions=batch.actions,
        instruction=list(batch.instruction),
        state=batch.state,
    )


def _request(batch: WorldModelBatch, info: WorldModelInfo) -> PredictRequest:
    """Sample 0 of a fitted batch as a :class:`PredictRequest` (HWC numpy, as the imagined branch builds it)."""

    def hwc(x: torch.Tensor) -> np.ndarray[Any, np.dtype[np.uint8]]:
        return np.ascontiguousarray(np.moveaxis(x.numpy(), -3, -1))

    return PredictRequest.build(
        info,
        current={v: hwc(batch.current[0, i]) for i, v in enumerate(info.views)},
        history={v: hwc(batch.history[0, i]) for i, v in enumerate(info.views)},
        history_valid=batch.history_valid[0].numpy(),
        control=hwc(batch.control[0]),
        actions=batch.actions[0].numpy(),
        instruction=batch.instruction[0],
        state=None if batch.state is None else batch.state[0].numpy(),
    )


def _rounded(x: Any) -> Any:
    if isinstance(x, float):
        return round(x, _DIGITS)
    if isinstance(x, dict):
        return {k: _rounded(v) for k, v in x.items()}
    if isinstance(x, list):
        return [_rounded(v) for v in x]
    return x


def _figures(summary: dict[str, Any], suffix: str = "") -> dict[str, Any]:
    """A :meth:`SingleStepScores.summarize` dict as JSON keys (``psnr_frozen``, ``per_view_frozen``, …)."""
    names = ("psnr", "ssim", "lpips", "psnr_pooled", "exact")
    out = {f"{m}{suffix}": summary[m] for m in names if m in summary}
    out[f"per_view{suffix}"] = summary["per_view"]
    out[f"per_frame{suffix}"] = summary["per_frame"]
    return out


def _gain(a: dict[str, Any], b: dict[str, Any], metric: str = "psnr") -> dict[str, float]:
    return {v: a["per_view"][v][metric] - b["per_view"][v][metric] for v in a["per_view"]}


def _gains(a: dict[str, Any], b: dict[str, Any]) -> dict[str, Any]:
    """PSNR differences a − b per view and overall, from per-image means and from pooled MSE."""
    return {
        "gain_over_frozen_db": _gain(a, b),
        "gain_over_frozen_db_overall": a["psnr"] - b["psnr"],
        "gain_over_frozen_pooled_db": _gain(a, b, "psnr_pooled"),
        "gain_over_frozen_pooled_db_overall": a["psnr_pooled"] - b["psnr_pooled"],
    }


# ---------------------------------------------------------------------- the benchmark


def run_world_model_bench(
    model: WorldModel,
    *,
    heldout: str | Path,
    no_history: WorldModel | None = None,
    steps: int | None = None,
    clips: int | None = 120,
    batch: int = 1,
    repeats: int = 20,
    seed: int = 0,
    rig: str | Path = SIM_RIG,
    progress: bool = True,
    cache_dir: str | Path | None = None,
    lpips_weights: Path | None = None,
) -> dict[str, Any]:
    """Single-step scores of ``model`` (and of the frozen baseline, and of ``no_history``) plus latency.

    ``clips`` caps the number of held-out clips (a subset drawn with ``seed``; ``None`` = all),
    ``batch`` is the ``predict_batch`` size for the scores (latency is always batch 1), ``steps`` is
    passed to every prediction (``None`` = the model's default). See the module docstring.
    """
    for name, value, low in (("batch", batch, 1), ("repeats", repeats, 1)):
        if isinstance(value, bool) or not isinstance(value, int) or value < low:
            raise ValueError(f"{name}: expected an integer >= {low}, got {value!r}")
    if clips is not None and (isinstance(clips, bool) or not isinstance(clips, int) or clips < 1):
        raise ValueError(f"clips: expected an integer >= 1 or None, got {clips!r}")
    t_start = time.perf_counter()
    info = model.info
    rig_cfg = RigConfig.load(rig)
    root = Path(heldout)
    store_spec = EpisodeStore(root).spec
    clip_spec = ClipSpec.for_dataset(
        store_spec.steps_per_frame, control_stride=CONTROL_STRIDE, future=info.future, history=info.history
    )
    dataset = ClipDataset(root, clip_spec, views=list(info.views), cache_dir=cache_dir)
    if len(dataset) == 0:
        raise ValueError(f"heldout: {root} has no clip of K={info.future} frames")
    if clips is None or clips >= len(dataset):
        chosen = list(range(len(dataset)))
    else:
        rng = np.random.default_rng(seed)
        chosen = sorted(int(i) for i in rng.choice(len(dataset), size=clips, replace=False))
    gamma = control_renderer(rig_cfg, info, stride=CONTROL_STRIDE)
    lpips_fn, lpips_reason = load_lpips(lpips_weights)
    models: dict[str, WorldModel] = {"model": model, "frozen": FrozenWorldModel(info)}
    if no_history is not None:
        if tuple(no_history.info.views) != tuple(info.views):  # batches are stacked in the model's view order
            got, want = list(no_history.info.views), list(info.views)
            raise ValueError(f"no_history: views {got} differ from the model's {want}")
        models["no_history"] = no_history
    scores = {name: SingleStepScores(lpips_fn) for name in models}

    t0 = time.perf_counter()
    first: WorldModelBatch | None = None  # the first clips, reused for the latency request
    with torch.no_grad():
        starts = range(0, len(chosen), batch)
        for b, i in enumerate(tqdm(starts, desc="single-step", unit="batch", disable=not progress)):
            raw = collate_clips([dataset[j] for j in chosen[i : i + batch]], gamma)
            assert raw.future is not None
            if first is None:
                first = raw
            for name, m in models.items():
                fitted = fit_batch(raw, m.info, name)
                target = resize_images(raw.future, m.info.height, m.info.width)
                pred = m.predict_batch(fitted, steps=steps, seed=seed + b)
                if pred.shape != target.shape or pred.dtype != torch.uint8:
                    raise ValueError(
                        f"{name}: predict_batch returned {pred.dtype} {tuple(pred.shape)}, "
                        f"expected uint8 {tuple(target.shape)}"
                    )
                scores[name].add(pred, target, m.info.views)
    single_step_s = time.perf_counter() - t0
    summaries = {name: s.summarize() for name, s in scores.items()}
    main_s, frozen_s = summaries["model"], summaries["frozen"]

    # Latency: one real held-out sample at the model's shape, as the imagined branch would call it.
    assert first is not None
    request = _request(fit_batch(first, info), info)
    times = []
    with torch.no_grad():
        for r in tqdm(range(WARMUP_CALLS + repeats), desc="latency", unit="call", disable=not progress):
            t = time.perf_counter()
            model.predict(request, steps=steps, seed=seed)
            if r >= WARMUP_CALLS:
                times.append(time.perf_counter() - t)
    latency_s = float(np.median(times))
    chunk_robot_s = info.future * CONTROL_STRIDE / rig_cfg.control_rate_hz

    result: dict[str, Any] = {
        "bench": "world-model",
        "model": type(model).__name__,
        "views": list(info.views),
        "image_size": [info.width, info.height],
        "dataset_image_size": [list(store_spec.views[v][::-1]) for v in info.views],
        "resized": any(tuple(store_spec.views[v]) != (info.height, info.width) for v in info.views),
        "K": info.future,
        "H_h": info.history,
        "stride": CONTROL_STRIDE,
        # The steps actually used: the argument, else the model's own default when it exposes one.
        "steps": steps if steps is not None else getattr(getattr(model, "config", None), "steps", None),
        "steps_is_default": steps is None,
        "heldout": heldout_description(root),
        "clips": len(chosen),
        "clips_available": len(dataset),
        "batch": batch,
        "seed": seed,
        **_figures(main_s),
        **_figures(frozen_s, "_frozen"),
        **_gains(main_s, frozen_s),
    }
    if lpips_fn is None:
        result["lpips_absent_reason"] = lpips_reason
    if no_history is not None:
        nh = summaries["no_history"]
        result["no_history"] = {
            "model": type(no_history).__name__,
            "history_frames_given": no_history.info.history,  # the ablation may still hide them inside
            **_figures(nh),
            **_gains(nh, frozen_s),
            "history_gain_db": _gain(main_s, nh),  # what the history frames add, per view
        }
    else:
        result["no_history"] = None
    result.update(
        {
            "single_step_s": single_step_s,
            "chunk_latency_ms": latency_s * 1000,
            "chunk_latency_ms_p90": float(np.percentile(times, 90)) * 1000,
            "latency_repeats": repeats,
            "chunk_robot_s": chunk_robot_s,
            "control_rate_hz": rig_cfg.control_rate_hz,
            "realtime_factor": chunk_robot_s / latency_s,
            "torch_threads": torch.get_num_threads(),
            "torch": torch.__version__,
            "machine": machine_info(),
            "wall_s": time.perf_counter() - t_start,
        }
    )
    return dict(_rounded(result))


# ---------------------------------------------------------------------- pilworld bench world-model


def _signed(x: Any) -> str:
    return f"{float(x):+.2f}"


# The summary table, one row per view (pilworld/bench/output.py aligns it).
WORLD_MODEL_COLUMNS = (
    Column("view", 18, "view", align="<"),
    Column("psnr", 8, "psnr", num),
    Column("frozen", 8, "frozen", num),
    Column("gain", 8, "gain", _signed),
    Column("pooled gain", 13, "pooled", _signed),
    Column("no-hist", 9, "no_history", num),  # only when the no-history ablation ran
)


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        "--checkpoint",
        type=Path,
        default=None,
        help="world-model checkpoint (default: v1, pilworld.world_model.V1_CHECKPOINT)",
    )
    parser.add_argument("--adapter", default=None, help="LoRA adapter of the checkpoint to apply (a task name)")
    add_rig(parser)
    parser.add_argument("--tasks", default="all", help="comma-separated tasks of the held-out runs (default all)")
    parser.add_argument("--episodes", type=int, default=2, help="held-out runs per task and checkpoint (default 2)")
    parser.add_argument(
        "--seed0", type=int, default=None, help="first held-out seed (default 1000000; training used 0-19)"
    )
    parser.add_argument(
        "--clips", type=int, default=120, help="max held-out clips scored, a seeded subset (default 120)"
    )
    parser.add_argument("--batch", type=int, default=1, help="clips per predict_batch call for the scores (default 1)")
    parser.add_argument("--steps", type=int, default=None, help="sampling steps (default: the model's)")
    parser.add_argument("--repeats", type=int, default=20, help="timed single-chunk calls for the latency (default 20)")
    parser.add_argument("--no-ablation", action="store_true", help="skip the no-history ablation figures")
    parser.add_argument("--lpips-weights", type=Path, default=None, help="folder holding the LPIPS AlexNet weights")
    parser.add_argument(
        "--workers", type=int, default=None, help="processes collecting the held-out runs (default: CPUs)"
    )
    parser.add_argument("--seed", type=int, default=0)
    add_json(parser)


def run(args: argparse.Namespace) -> int:
    """The held-out set (collected once, then cached), the model's scores against the frozen baseline, latency."""
    # Imported here: the checkpoint loader pulls in the model code, which parsing the options does not need.
    import pilworld.world_model as world_model
    from pilworld.world_model.loader import load_world_model
    from simrig.tasks import TASK_NAMES

    # v1 by default: the bench's presets, steps and open-loop figures (docs/world_model.md) are v1's.
    checkpoint = args.checkpoint or getattr(world_model, "V1_CHECKPOINT", None)
    if checkpoint is None:
        raise ValueError("--checkpoint: required (pilworld.world_model defines no V1_CHECKPOINT)")
    if not Path(checkpoint).exists():
        raise FileNotFoundError(f"--checkpoint: {checkpoint} not found")
    tasks = parse_names(args.tasks, list(TASK_NAMES), "--tasks")
    model = load_world_model(Path(checkpoint), adapter=args.adapter)
    no_history = None
    if not args.no_ablation and isinstance(model, HistoryAblation):
        no_history = model.without_history()
    root = heldout_dataset(
        args.rig,
        tasks=tasks,
        episodes=args.episodes,
        seed0=HELDOUT_SEED0 if args.seed0 is None else args.seed0,
        workers=args.workers,
        progress=not args.json,
    )
    result = run_world_model_bench(
        model,
        heldout=root,
        no_history=no_history,
        steps=args.steps,
        clips=args.clips,
        batch=args.batch,
        repeats=args.repeats,
        seed=args.seed,
        rig=args.rig,
        progress=not args.json,
        lpips_weights=args.lpips_weights,
    )
    result = {"checkpoint": str(checkpoint), "adapter": args.adapter, **result}
    return emit(args, result, summary_lines(result))


def summary_lines(result: dict[str, Any]) -> list[str]:
    """PSNR and SSIM against the frozen baseline, the per-view table, LPIPS and latency."""
    w, h = result["image_size"]
    nh = result["no_history"]
    rows = [
        {
            "view": view,
            "psnr": fig["psnr"],
            "frozen": result["per_view_frozen"][view]["psnr"],
            "gain": result["gain_over_frozen_db"][view],
            "pooled": result["gain_over_frozen_pooled_db"][view],
            "no_history": nh["per_view"][view]["psnr"] if nh else None,
        }
        for view, fig in result["per_view"].items()
    ]
    lines = [
        f"world-model ({result['model']}, {w}x{h}, K={result['K']}): {result['clips']} held-out clips, "
        f"PSNR {result['psnr']:.2f} dB (frozen {result['psnr_frozen']:.2f}), "
        f"SSIM {result['ssim']:.3f} (frozen {result['ssim_frozen']:.3f})",
        *table(WORLD_MODEL_COLUMNS if nh else WORLD_MODEL_COLUMNS[:-1], rows),
    ]
    exact = {v: f["exact"] for v, f in result["per_view_frozen"].items() if f["exact"] > 0}
    if exact:  # these frames score the 100 dB cap and lift psnr_frozen
        shares = ", ".join(f"{v} {x:.0%}" for v, x in exact.items())
        lines.append(f"  frozen baseline bit-exact (static view, PSNR capped at 100 dB): {shares}")
    if "lpips" in result:
        lines.append(f"  LPIPS {result['lpips']:.4f} (frozen {result['lpips_frozen']:.4f})")
    else:
        lines.append(f"  LPIPS not computed: {result['lpips_absent_reason']}")
    lines.append(
        f"  latency {result['chunk_latency_ms']:.1f} ms per chunk (p90 {result['chunk_latency_ms_p90']:.1f}, "
        f"steps {result['steps'] if result['steps'] is not None else 'default'}, {result['torch_threads']} threads), "
        f"realtime factor {result['realtime_factor']:.2f}"
    )
    return lines
