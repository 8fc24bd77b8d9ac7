"""``pilworld bench speed-accuracy``: world-model presets × resolutions × sampling steps, latency against error.

Every **point** is one trained model run with one number of Euler steps (1, 2, 4, 8, 16):

* ``chunk_latency_ms`` — median of batch-1 ``predict`` calls (K frames × 3 views), as the imagined
  branch calls it, at the rig's 128×128 (a model trained at a lower resolution runs through
  :class:`~pilworld.world_model.resized.ResizedWorldModel`, so its resizing is in the time);
* single-step accuracy on held-out clips (seeds 1,000,000+; :mod:`pilworld.bench.world_model`), scored
  **at the rig's resolution** for every model (a 32×32 model's frames upsampled to 128×128 — the size the
  judges see), so points of different resolutions compare: head-view pooled PSNR and SSIM;
* without ``--quick``: |ΔSR| and HFR in closed loop on a small paired protocol (3 tasks × 2 checkpoints
  × 3 subtasks, real branches shared between points).

The **Pareto front** is the set of points no other point beats on both latency and head-view PSNR.
The **default** is chosen at the knee: the fastest front point whose head-view PSNR is within
:data:`KNEE_DB` of the best point's — the smallest model that reaches the accuracy — among those that keep
real time (realtime factor ≥ 1). The shipped default (``small``, 1 step) is compared against it.

Trained models: ``small`` 128×128 is the shipped model (no adapter here, so every point is the stage-1
model); ``tiny`` at 32×32 and 64×64 are in ``weights/bench`` (same data, 1,500 VAE + 3,500 Ψ_θ steps).
``base`` (61.6 M parameters) is timed but not trained on this CPU; its point has no accuracy and is
left out of the front (``untrained``).
"""

from __future__ import annotations

import time
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from pilworld.bench.common import machine_info
from pilworld.bench.variants import ModelVariant, PairedProtocol, bench_model, evaluate_variants

STEPS = (1, 2, 4, 8, 16)
QUICK_STEPS = (1, 2, 4, 8, 16)
CLOSED_LOOP_SUBTASKS = 3  # per task × checkpoint: 18 pairs per point
KNEE_DB = 0.25  # head-view PSNR within this of the best counts as "reaches the accuracy"
QUICK_CLIPS = 24
# Timed calls per point. Quick mode takes the median of 3: the untrained `base` preset costs ~0.5 s per
# Euler step, so 10 calls at 16 steps alone would eat a third of the 5-minute budget.
QUICK_REPEATS = 3
FULL_REPEATS = 10
FULL_CLIPS = 96
HEAD = "cam_high"


@dataclass(frozen=True)
class TrainedModel:
    """A model folder and what it is (preset and native size)."""

    preset: str
    size: int
    path: str  # "" = the packaged checkpoint
    untrained: bool = False

    @property
    def key(self) -> str:
        return f"{self.preset}_{self.size}"


def default_models() -> list[TrainedModel]:
    return [
        TrainedModel("tiny", 32, bench_model("tiny_32")),
        TrainedModel("tiny", 64, bench_model("tiny_64")),
        TrainedModel("small", 128, ""),
        TrainedModel("base", 128, "", untrained=True),
    ]


def _check_model(m: TrainedModel, path: Path) -> None:
    """Raise ``FileNotFoundError`` naming the preset and size when ``path`` holds no model."""
    if not (path / "config.json").is_file():
        raise FileNotFoundError(
            f"speed-accuracy: no {m.preset} {m.size}x{m.size} model at {path}; docs/RESULTS.md has the "
            "command that trains it"
        )


def _load(m: TrainedModel, rig_size: tuple[int, int]) -> Any:
    import torch

    from pilworld.world_model import V1_CHECKPOINT
    from pilworld.world_model.checkpoint import load_world_model
    from pilworld.world_model.config import preset
    from pilworld.world_model.model import PilWorldModel
    from pilworld.world_model.resized import ResizedWorldModel

    if m.untrained:
        with torch.random.fork_rng(devices=[]):
            torch.manual_seed(0)
            model: Any = PilWorldModel(preset(m.preset, height=m.size, width=m.size)).eval()
    else:
        path = Path(m.path) if m.path else Path(V1_CHECKPOINT)  # the sweep's presets and steps are v1's
        _check_model(m, path)
        model = load_world_model(path)
    if (model.info.width, model.info.height) != rig_size:
        model = ResizedWorldModel(model, height=rig_size[1], width=rig_size[0])
    return model


def pareto_front(points: Sequence[dict[str, Any]], *, x: str = "chunk_latency_ms", y: str = "psnr_head") -> list[str]:
    """Ids of the points not dominated: none other is at most as slow and at least as accurate, one strictly."""
    scored = [p for p in points if p.get(y) is not None]
    front = []
    for p in scored:
        dominated = any(q is not p and q[x] <= p[x] and q[y] >= p[y] and (q[x] < p[x] or q[y] > p[y]) for q in scored)
        if not dominated:
            front.append(p["id"])
    return sorted(front, key=lambda i: next(p[x] for p in scored if p["id"] == i))


def choose_default(points: Sequence[dict[str, Any]], front: Sequence[str]) -> dict[str, Any]:
    """The knee: the fastest real-time front point within KNEE_DB of the best head-view PSNR."""
    on_front = [p for p in points if p["id"] in front]
    if not on_front:
        raise ValueError("speed-accuracy: no point has an accuracy (nothing to choose from)")
    best = max(p["psnr_head"] for p in on_front)
    good = [p for p in on_front if p["psnr_head"] >= best - KNEE_DB and p["realtime_factor"] >= 1.0]
    pick = min(good or on_front, key=lambda p: p["chunk_latency_ms"])
    return {
        "id": pick["id"],
        "preset": pick["preset"],
        "size": pick["size"],
        "steps": pick["steps"],
        "chunk_latency_ms": pick["chunk_latency_ms"],
        "psnr_head": pick["psnr_head"],
        "best_psnr_head": best,
        "rule": f"fastest real-time point of the front within {KNEE_DB} dB of the best head-view PSNR",
    }


def run_speed_accuracy(
    *,
    rig: str | Path,
    quick: bool = False,
    models: Sequence[TrainedModel] | None = None,
    steps: Sequence[int] | None = None,
    clips: int | None = None,
    repeats: int | None = None,
    out: str | Path = "bench_runs/speed-accuracy",
    closed_loop: bool | None = None,
    workers: int | None = None,
    progress: bool = True,
) -> dict[str, Any]:
    from hw_drivers.sim.tasks import TASK_NAMES
    from pilworld.bench.world_model import HELDOUT_SEED0, heldout_dataset, run_world_model_bench
    from pilworld.config.rig import RigConfig

    t0 = time.monotonic()
    rig_cfg = RigConfig.load(rig)
    rig_size = (rig_cfg.image_size.width, rig_cfg.image_size.height)
    chosen_models = list(models or default_models())
    chosen_steps = tuple(steps or (QUICK_STEPS if quick else STEPS))
    n_clips = clips or (QUICK_CLIPS if quick else FULL_CLIPS)
    # `is None`, not `or`: an explicit 0 must reach the bench's own check and be refused, not become the default.
    n_repeats = repeats if repeats is not None else (QUICK_REPEATS if quick else FULL_REPEATS)
    loop = (not quick) if closed_loop is None else closed_loop
    for m in chosen_models:  # a missing model fails before minutes of data collection and earlier points
        if not m.untrained and m.path:
            _check_model(m, Path(m.path))
    # The held-out set of `pilworld bench world-model` (same arguments, so its cache is shared).
    heldout = heldout_dataset(rig, tasks=list(TASK_NAMES), episodes=2, seed0=HELDOUT_SEED0, progress=progress)
    points: list[dict[str, Any]] = []
    for m in chosen_models:
        model = _load(m, rig_size)
        for s in chosen_steps:
            if progress:
                print(f"[speed-accuracy] {m.key} steps={s}", flush=True)
            r = run_world_model_bench(
                model,
                heldout=heldout,
                steps=s,
                clips=1 if m.untrained else n_clips,
                repeats=n_repeats,
                rig=rig,
                progress=False,
            )
            head = r["per_view"][HEAD]
            point: dict[str, Any] = {
                "id": f"{m.key}_s{s}",
                "preset": m.preset,
                "size": f"{m.size}x{m.size}",
                "steps": s,
                "chunk_latency_ms": r["chunk_latency_ms"],
                "realtime_factor": r["realtime_factor"],
                "psnr_head": None if m.untrained else head["psnr_pooled"],
                "ssim_head": None if m.untrained else head["ssim"],
                "psnr_pooled": None if m.untrained else r["psnr_pooled"],
                "gain_over_frozen_head_db": None if m.untrained else r["gain_over_frozen_pooled_db"][HEAD],
                "abs_delta_sr": None,
                "hfr": None,
                "clips": r["clips"],
            }
            if m.untrained:
                point["untrained"] = "not trained on this CPU (timed with random weights)"
            points.append(point)
    reason = "quick mode: closed loop not run" if quick and closed_loop is None else "closed_loop=False"
    closed: dict[str, Any] = {"skipped": reason} if not loop else {}
    if loop:
        closed = _closed_loop(points, chosen_models, out, rig=rig, workers=workers, progress=progress)
    front = pareto_front(points)
    default = choose_default(points, front)
    shipped = next((p for p in points if p["preset"] == "small" and p["steps"] == 1), None)
    return {
        "bench": "speed-accuracy",
        "quick": quick,
        "points": points,
        "front": [p for p in points if p["id"] in front],
        "front_ids": front,
        "default": default,
        "shipped_default": {"preset": "small", "steps": 1, "agrees": default["id"] == "small_128_s1"}
        | ({"chunk_latency_ms": shipped["chunk_latency_ms"], "psnr_head": shipped["psnr_head"]} if shipped else {}),
        "closed_loop": closed,
        "heldout_clips": n_clips,
        "latency_repeats": n_repeats,
        "machine": machine_info(),
        "wall_s": round(time.monotonic() - t0, 1),
    }


def _closed_loop(
    points: list[dict[str, Any]],
    models: Sequence[TrainedModel],
    out: str | Path,
    *,
    rig: str | Path,
    workers: int | None,
    progress: bool,
) -> dict[str, Any]:
    """|ΔSR| and HFR of every trained point on one small protocol (real branches run once)."""
    from pilworld.bench.paired import QUICK_CHECKPOINTS, protocol

    base = protocol(True)
    proto = PairedProtocol(base.tasks, QUICK_CHECKPOINTS, CLOSED_LOOP_SUBTASKS, base.rounds, base.seed)
    by_key = {m.key: m for m in models}
    variants = []
    for p in points:
        m = by_key[f"{p['preset']}_{p['size'].split('x')[0]}"]
        if m.untrained:
            continue
        variants.append(
            ModelVariant(p["id"], p["id"], m.path, adapter="none", steps=p["steps"], resize=True, role="point")
        )
    results = evaluate_variants(variants, proto, out, rig=rig, workers=workers, progress=progress, single_step=False)
    for p in points:
        if p["id"] in results:
            o = results[p["id"]]["metrics"]["overall"]
            p["abs_delta_sr"] = o["abs_delta_sr"]
            p["hfr"] = o["hfr"]
            p["sr_imag"] = o["sr_imag"]
    return {"pairs_per_point": proto.pairs, "checkpoints": list(proto.checkpoints), "out": str(out)}
