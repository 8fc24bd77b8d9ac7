"""``pilworld bench speed-accuracy``: chunk latency against closed-loop accuracy, for every model size and step count.

The question (docs/RESULTS.md, section 2): which is the **smallest model that predicts closed-loop
outcomes**, and what does each step up in size or in sampling steps buy? Accuracy here is what the bench is
for — whether the imagined branch reaches the real branch's verdict — so the front and the knee are chosen on
closed-loop |ΔSR| and HFR; single-step image error is kept as a secondary column (it ranked v1's presets, and
v1 fails every rollout).

**Points.** One point per world model and number of sampling steps:

* **v1** (the paper-style latent flow model, :class:`~pilworld.world_model.latent.model.PilWorldModel`): the trained
  ``tiny`` 32×32 and 64×64 (``weights/bench/tiny_32|tiny_64``) and ``small`` 128×128
  (:data:`~pilworld.world_model.V1_CHECKPOINT`), each at 1, 2, 4, 8 and 16 Euler steps, run at the rig's
  128×128 through :class:`~pilworld.world_model.resized.ResizedWorldModel` (resizing in the time and in the
  frames the judges see), no task adapters. ``base`` (61.6 M parameters) is not trained on this CPU: it is
  timed with seeded random weights and is never on the front nor the knee (``untrained``).
* **v2** (the shipped model, :data:`~pilworld.world_model.DEFAULT_CHECKPOINT`, a compositing U-Net over
  geometry layers with tracked objects): ``v2_shipped``. It is deterministic — one pass, no sampling steps —
  so it is one point (``steps`` 1, with a note). It runs at the rig's size, bound to the rig's geometry,
  never resized. **v2 sizes** (:data:`V2_SIZES`: U-Net width 8 or 32, or work size 64² instead of 16 and
  32²) are points when their weights exist in ``weights/bench/<name>`` (``scripts/train-bench-variants
  v2_w8 v2_w32 v2_work64`` makes them, same data, cache and 6,000 steps as the shipped model); a missing one
  is listed as ``{"id": ..., "skipped": "not trained: ..."}`` and left out of front and knee.

**Per point:**

* ``chunk_latency_ms`` — the median wall time of **one whole imagined round**, ``ImaginedEnv.step(chunk)`` at
  batch 1 from one simulated start (control video, the model's layers, the prediction of K frames × 3 views,
  the predicted state), timed round-robin over all points (:func:`pilworld.bench.chunk_latency.time_rounds`,
  as ``pilworld bench chunk-latency``). The whole round, because v2's cost is in its geometry layers and
  objects, not its network; the same round for v1 and v2, so they compare. ``predict_latency_ms`` is the
  model call alone within the same rounds. The chart, the front and ``realtime_factor`` (robot time of one
  chunk, K·Δ / control rate = 1.5 s, over the round) use the whole round.
* ``params`` — ``sum(p.numel() for p in model.parameters())``: v1's VAE and denoiser, v2's U-Net and painter.
* single-step accuracy on :data:`FULL_CLIPS` held-out clips (seeds 1,000,000+; :mod:`pilworld.bench.world_model`),
  scored at the rig's resolution: head-view pooled PSNR and SSIM (secondary). v2 is scored through its
  ``predict_batch`` with the clips' joint states, which gives it no history frames (its memory layer is empty):
  a lower bound.
* closed loop (:func:`~pilworld.bench.variants.evaluate_variants`, real branches run once and shared by every
  point): |ΔSR|, HFR, SR_imag, SR_real and their 95 % intervals on 3 tasks × 2 checkpoints ×
  :data:`CLOSED_LOOP_SUBTASKS` subtasks = 18 pairs, for every trained v2 point and v1 at 1 and 16 steps
  (:func:`closed_loop_steps`; v1 at 2, 4 and 8 steps keeps its latency and single-step figures).

``stages_s`` gives the wall time of each stage (latency, single step, closed loop).

**Quick mode** (``--quick``): v1 at 1, 4 and 16 steps, 24 held-out clips, 1 + 3 timed rounds per point, and the
closed loop too, small: 1 subtask per task × checkpoint (6 pairs), v1 at 1 step only plus every v2 point (the
other quick points get latency and single-step figures, no closed loop, and are never on the quick front). With
6 pairs one pair is 17 points of SR, so the quick knee only separates models that fail every rollout from ones
that do not. Measured 2026-12-05 on the 2-core machine while another benchmark kept it busy (load ≈ 8): 1,372 s,
of which 250 s closed loop; on idle cores the old quick mode's parts (172 s for 20 points) suggest ~4 minutes.

**Front and knee.** The front is the set of points with closed-loop figures that no other point beats on
(latency ↓, |ΔSR| ↓, HFR ↑). The **knee** — the smallest model that reaches the accuracy — is, among the
real-time points (realtime factor ≥ 1) whose |ΔSR| is within
:func:`~pilworld.bench.speed_accuracy_front.knee_tolerances` of the best point's and whose HFR is within
:data:`~pilworld.bench.speed_accuracy_front.KNEE_HFR` of the best HFR, the one with the **fewest
parameters**, ties by latency. ``shipped_default`` compares it with ``v2_shipped`` (``agrees``, else what the
default should become). ``steps_buy`` gives, per v1 model, what 2…16 steps change against 1 step;
``size_buy`` what each size step changes (tiny 32² → tiny 64² → small 128² → base; v2 width 8 → 16 → 32 and
work size 32² → 64²; and v1 small → v2, another model rather than a size). ``single_step_knee`` is the old
rule, for contrast: the fastest real-time point of the (latency, head PSNR) front within
:data:`~pilworld.bench.speed_accuracy_front.KNEE_DB` of the best PSNR. These rules live in
:mod:`pilworld.bench.speed_accuracy_front`; docs/RESULTS.md, section 2, has the figures.
"""

from __future__ import annotations

import argparse
import time
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from pilworld.bench.common import machine_info
from pilworld.bench.flags import add_json, add_rig, run_folder
from pilworld.bench.output import Column, emit, num, pct, table
from pilworld.bench.speed_accuracy_front import (
    SHIPPED,
    SINGLE_STEP_OBJECTIVES,
    choose_knee,
    choose_single_step_default,
    pareto_front,
    shipped_verdict,
    size_buy,
    steps_buy,
)
from pilworld.bench.variants import ModelVariant, PairedProtocol, bench_model, evaluate_variants
from pilworld.options.bounds import at_least_one

STEPS = (1, 2, 4, 8, 16)
QUICK_STEPS = (1, 4, 16)
QUICK_CLOSED_LOOP_STEPS = (1,)  # quick mode: v1 points in closed loop (every v2 point runs)
CLOSED_LOOP_SUBTASKS = 3  # per task × checkpoint: 18 pairs per point
QUICK_CLOSED_LOOP_SUBTASKS = 1  # 6 pairs per point
QUICK_CLIPS = 24
# Single-step PSNR is the secondary column; 48 clips (each 8 frames x 3 views) halve the stage that was the
# set's largest after the paired bench (17 points x 96 clips: 1,392 s of 1,886 on a busy machine, 2026-12-05).
FULL_CLIPS = 48
# Timed rounds per point (after warm-up rounds). Quick mode takes the median of 3: the untrained `base` preset
# costs ~0.1 s per Euler step on an idle CPU, so 10 calls at 16 steps would eat a large part of 5 minutes.
QUICK_REPEATS = 3
FULL_REPEATS = 10
QUICK_WARMUP = 1
FULL_WARMUP = 2
LATENCY_TASK = "sort_cubes"
LATENCY = (
    "whole imagined round: ImaginedEnv.step(chunk) at batch 1 (control video, the model's layers, prediction of "
    "K frames x 3 views, predicted state), median, round-robin over the points; predict_latency_ms is the model "
    "call alone in the same rounds"
)
HEAD = "cam_high"
V2_NO_STEPS = "v2 is deterministic: one pass, no sampling steps (the steps argument is ignored)"

# v2 at other sizes, all else as shipped (same data, cache, steps): name → config fields, what changes.
V2_SIZES: tuple[tuple[str, Mapping[str, int], str], ...] = (
    ("v2_w8", {"width": 8}, "U-Net width 8 (shipped 16)"),
    ("v2_w32", {"width": 32}, "U-Net width 32 (shipped 16)"),
    ("v2_work64", {"work_size": 64}, "U-Net work size 64x64 (shipped 32x32)"),
)


@dataclass(frozen=True)
class TrainedModel:
    """A model folder and what it is: family (v1 / v2), preset and native size."""

    preset: str  # v1: "tiny" | "small" | "base"; v2: "v2"
    size: int
    path: str  # the model folder; "" = the family's packaged checkpoint
    untrained: bool = False  # v1 only: the preset with seeded random weights, timed only
    family: str = "v1"
    name: str = ""  # a v2 model's point id ("v2_shipped", "v2_w8"); v1 points are "<preset>_<size>_s<steps>"
    optional: bool = False  # missing weights make a skipped point instead of an error
    trained_by: str = ""  # the command that makes the weights
    expect: tuple[tuple[str, int], ...] = ()  # v2 config fields its folder must have (width, work_size)
    note: str = ""

    def __post_init__(self) -> None:
        if self.family not in ("v1", "v2"):
            raise ValueError(f"model family: expected 'v1' or 'v2', got {self.family!r}")
        if self.family == "v2" and (self.untrained or not self.name):
            raise ValueError("a v2 model needs a name (its point id) and trained weights")

    @property
    def key(self) -> str:
        return self.name or f"{self.preset}_{self.size}"

    @property
    def folder(self) -> Path:
        from pilworld.world_model import DEFAULT_CHECKPOINT, V1_CHECKPOINT

        if self.path:
            return Path(self.path)
        return Path(V1_CHECKPOINT) if self.family == "v1" else Path(DEFAULT_CHECKPOINT)

    def point_id(self, steps: int) -> str:
        return self.key if self.family == "v2" else f"{self.key}_s{steps}"


def v2_size_models() -> list[TrainedModel]:
    return [
        TrainedModel(
            "v2",
            128,
            bench_model(name),
            family="v2",
            name=name,
            optional=True,
            trained_by=f"scripts/train-bench-variants {name}",
            expect=tuple(sorted(fields.items())),
            note=what,
        )
        for name, fields, what in V2_SIZES
    ]


def default_models() -> list[TrainedModel]:
    from pilworld.world_model import DEFAULT_CHECKPOINT, V1_CHECKPOINT

    return [
        TrainedModel("tiny", 32, bench_model("tiny_32")),
        TrainedModel("tiny", 64, bench_model("tiny_64")),
        TrainedModel("small", 128, str(V1_CHECKPOINT)),
        TrainedModel("base", 128, "", untrained=True),
        TrainedModel("v2", 128, str(DEFAULT_CHECKPOINT), family="v2", name=SHIPPED, note="the shipped model"),
        *v2_size_models(),
    ]


def _missing(m: TrainedModel) -> str | None:
    """Why ``m`` cannot be loaded (no model folder), or ``None``."""
    if m.untrained or (m.folder / "config.json").is_file():
        return None
    return f"not trained: {m.trained_by}" if m.trained_by else f"no model at {m.folder}"


def _check_model(m: TrainedModel) -> None:
    """Raise ``FileNotFoundError`` naming the model when its folder holds none."""
    if _missing(m) is not None:
        how = m.trained_by or "docs/RESULTS.md has the command that trains it"
        raise FileNotFoundError(f"speed-accuracy: no {m.preset} {m.size}x{m.size} model at {m.folder}; {how}")


def _load(m: TrainedModel, rig: Any) -> Any:
    """``m`` ready for the rig (a :class:`~pilworld.config.rig.RigConfig`): v1 resized to its image size, v2 bound
    to its geometry (never resized: v2 composites at the rig's size)."""
    import torch

    from pilworld.world_model.latent.config import preset
    from pilworld.world_model.latent.model import PilWorldModel
    from pilworld.world_model.loader import load_world_model
    from pilworld.world_model.resized import ResizedWorldModel

    size = (rig.image_size.width, rig.image_size.height)
    if m.untrained:
        with torch.random.fork_rng(devices=[]):
            torch.manual_seed(0)
            model: Any = PilWorldModel(preset(m.preset, height=m.size, width=m.size)).eval()
    else:
        _check_model(m)
        model = load_world_model(m.folder)
    if m.family == "v2":
        from pilworld.world_model.composite.model import CompositeWorldModel

        if not isinstance(model, CompositeWorldModel):
            raise ValueError(f"speed-accuracy: {m.key} at {m.folder} is not a v2 (composite) world model")
        wrong = {k: getattr(model.config, k) for k, v in m.expect if getattr(model.config, k) != v}
        if wrong:
            raise ValueError(f"speed-accuracy: {m.key} at {m.folder} has {wrong}, expected {dict(m.expect)}")
        model.bind_rig(rig)  # ValueError when the rig's image size is not the model's
        return model
    if not isinstance(model, PilWorldModel):
        raise ValueError(f"speed-accuracy: {m.key} at {m.folder} is not a v1 world model")
    if (model.info.width, model.info.height) != size:
        model = ResizedWorldModel(model, height=size[1], width=size[0])
    return model


def parameter_count(model: Any) -> int:
    """Parameters of the network itself (a resized model's inner one): v1's VAE + denoiser, v2's U-Net + painter."""
    inner = getattr(model, "model", model)
    return int(sum(p.numel() for p in inner.parameters()))


class _Timed:
    """``model`` with its prediction calls timed (what the imagined branch calls: ``predict_with_state`` when the
    model has it, else ``predict``); everything else passes through."""

    def __init__(self, model: Any) -> None:
        self.model = model
        self.seconds: list[float] = []

    @property
    def info(self) -> Any:
        return self.model.info

    def __getattr__(self, name: str) -> Any:
        attr = getattr(self.__dict__["model"], name)
        if name not in ("predict", "predict_with_state"):
            return attr

        def timed(*args: Any, **kwargs: Any) -> Any:
            t = time.perf_counter()
            try:
                return attr(*args, **kwargs)
            finally:
                self.seconds.append(time.perf_counter() - t)

        return timed


# ---------------------------------------------------------------------- the sweep


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
    subtasks: int | None = None,
    workers: int | None = None,
    progress: bool = True,
) -> dict[str, Any]:
    """The sweep (see the module docstring). ``closed_loop=False`` skips the closed loop (then there is no knee:
    ``default`` says why); ``subtasks`` overrides the closed loop's subtasks per task × checkpoint."""
    from pilworld.bench.chunk_latency import imagined_env, round_setup, time_rounds
    from pilworld.bench.world_model import HELDOUT_SEED0, heldout_dataset, run_world_model_bench
    from pilworld.config.rig import RigConfig
    from simrig.tasks import TASK_NAMES

    t0 = time.monotonic()
    rig_cfg = RigConfig.load(rig)
    chosen_models = list(models if models is not None else default_models())
    chosen_steps = tuple(steps or (QUICK_STEPS if quick else STEPS))
    n_clips = clips or (QUICK_CLIPS if quick else FULL_CLIPS)
    n_repeats = repeats if repeats is not None else (QUICK_REPEATS if quick else FULL_REPEATS)
    if n_repeats < 1:
        raise ValueError(f"repeats: expected at least 1 timed round per point, got {n_repeats}")
    warmup = QUICK_WARMUP if quick else FULL_WARMUP
    loop = True if closed_loop is None else closed_loop
    n_sub = subtasks or (QUICK_CLOSED_LOOP_SUBTASKS if quick else CLOSED_LOOP_SUBTASKS)
    loop_steps = closed_loop_steps(chosen_steps, quick)
    if len({m.key for m in chosen_models}) != len(chosen_models):
        raise ValueError(f"models: a model is listed twice: {[m.key for m in chosen_models]}")
    present: list[TrainedModel] = []
    skipped: dict[str, str] = {}
    for m in chosen_models:  # a missing model fails before minutes of data collection and earlier points
        reason = _missing(m)
        if reason is not None and m.optional:
            skipped[m.key] = reason
        elif reason is not None:
            _check_model(m)
        else:
            present.append(m)

    points: list[dict[str, Any]] = []
    loaded: dict[str, Any] = {}
    for m in chosen_models:
        for s in (1,) if m.family == "v2" else chosen_steps:
            point: dict[str, Any] = {
                "id": m.point_id(s),
                "model": m.key,
                "family": m.family,
                "preset": m.preset,
                "size": f"{m.size}x{m.size}",
                "steps": s,
            }
            if m.family == "v2":
                point["note"] = f"{m.note + '; ' if m.note else ''}{V2_NO_STEPS}"
            if m.key in skipped:
                points.append(point | {"skipped": skipped[m.key], "params": None})
                continue
            if m.key not in loaded:
                loaded[m.key] = _load(m, rig_cfg)
            point |= {"path": None if m.untrained else str(m.folder), "params": parameter_count(loaded[m.key])}
            if m.untrained:
                point["untrained"] = "not trained on this CPU (timed with seeded random weights)"
            points.append(point)
    live = [p for p in points if not p.get("skipped")]
    by_model = {m.key: m for m in chosen_models}

    stages: dict[str, float] = {}
    t_stage = time.monotonic()
    # 1. Latency: one whole imagined round per point, round-robin (a slowing machine slows every point alike).
    if progress:
        print(f"[speed-accuracy] timing {len(live)} points: {warmup} + {n_repeats} rounds each", flush=True)
    setup = round_setup(rig, LATENCY_TASK)
    timed = {p["id"]: _Timed(loaded[p["model"]]) for p in live}
    envs = {
        p["id"]: imagined_env(timed[p["id"]], setup, steps=None if p["family"] == "v2" else p["steps"]) for p in live
    }
    rounds = time_rounds(envs, setup, repeats=n_repeats, warmup=warmup)
    chunk_robot_s = setup.spec.frames * setup.spec.stride / rig_cfg.control_rate_hz
    for p in live:
        ms = float(np.median(rounds[p["id"]]))
        predict = timed[p["id"]].seconds[-n_repeats:]
        p["chunk_latency_ms"] = round(ms, 2)
        p["chunk_latency_ms_p90"] = round(float(np.percentile(rounds[p["id"]], 90)), 2)
        p["predict_latency_ms"] = round(1000.0 * float(np.median(predict)), 2)
        p["realtime_factor"] = round(chunk_robot_s * 1000.0 / ms, 3)

    stages["latency"] = round(time.monotonic() - t_stage, 1)
    t_stage = time.monotonic()
    # 2. Single-step accuracy on held-out clips (the held-out set of `pilworld bench world-model`, its cache shared).
    heldout = None
    if any(not p.get("untrained") for p in live):
        heldout = heldout_dataset(rig, tasks=list(TASK_NAMES), episodes=2, seed0=HELDOUT_SEED0, progress=progress)
    for p in live:
        p |= {k: None for k in ("psnr_head", "ssim_head", "psnr_pooled", "gain_over_frozen_head_db")}
        p |= {"clips": 0, "abs_delta_sr": None, "hfr": None, "sr_imag": None, "sr_real": None}
        if p.get("untrained"):
            continue
        if progress:
            print(f"[speed-accuracy] single-step {p['id']}", flush=True)
        assert heldout is not None
        r = run_world_model_bench(
            loaded[p["model"]],
            heldout=heldout,
            steps=None if p["family"] == "v2" else p["steps"],
            clips=n_clips,
            repeats=1,  # latency is timed above, as whole rounds
            rig=rig,
            progress=False,
        )
        head = r["per_view"][HEAD]
        p |= {
            "psnr_head": head["psnr_pooled"],
            "ssim_head": head["ssim"],
            "psnr_pooled": r["psnr_pooled"],
            "gain_over_frozen_head_db": r["gain_over_frozen_pooled_db"][HEAD],
            "clips": r["clips"],
        }
        if p["family"] == "v2":
            p["single_step_note"] = "predict_batch with the clips' joint states and no history frames (memory empty)"

    stages["single_step"] = round(time.monotonic() - t_stage, 1)
    t_stage = time.monotonic()
    # 3. Closed loop: every v2 point and v1 at closed_loop_steps (1 and 16; quick: 1), real branches shared.
    if loop:
        closed = _closed_loop(
            points, by_model, out, rig=rig, subtasks=n_sub, steps=loop_steps, workers=workers, progress=progress
        )
    else:
        closed = {"skipped": "closed_loop=False"}
    stages["closed_loop"] = round(time.monotonic() - t_stage, 1)

    front = pareto_front(points)
    default: dict[str, Any]
    if loop:
        default = choose_knee(points, front, pairs=closed["pairs_per_point"])
    else:
        default = {"id": None, "none": "closed loop not run: the knee is chosen on closed-loop accuracy"}
    single_front = pareto_front(points, SINGLE_STEP_OBJECTIVES)
    try:
        single_step: dict[str, Any] = choose_single_step_default(points, single_front)
    except ValueError as err:
        single_step = {"id": None, "none": str(err), "front_ids": single_front}
    return {
        "bench": "speed-accuracy",
        "quick": quick,
        "latency": {
            "measures": LATENCY,
            "task": LATENCY_TASK,
            "repeats": n_repeats,
            "warmup": warmup,
            "chunk_robot_s": chunk_robot_s,
        },
        "points": points,
        "front": [p for p in points if p["id"] in front],
        "front_ids": front,
        "default": default,
        "shipped_default": shipped_verdict(points, default) if loop else {"id": SHIPPED, "agrees": None},
        "single_step_knee": single_step,
        "steps_buy": steps_buy(points),
        "size_buy": size_buy(points),
        "closed_loop": closed,
        "heldout_clips": n_clips,
        "latency_repeats": n_repeats,
        "machine": machine_info(),
        "stages_s": stages,
        "wall_s": round(time.monotonic() - t0, 1),
    }


def closed_loop_steps(chosen: Sequence[int], quick: bool) -> tuple[int, ...]:
    """The v1 sampling steps that run in closed loop (every v2 point runs): quick, 1 step; full, the fewest and
    the most of ``chosen`` (1 and 16 by default).

    The steps between cost ~9 minutes of the full set's 90 on a 2-core CPU and told nothing apart on 2026-12-05:
    every v1 point at 1…16 steps failed every rollout (|ΔSR| 50-56, HFR < 0.08). Fewest → most answers what
    sampling steps buy in closed loop; the points between keep their latency and single-step figures.
    """
    if quick:
        return QUICK_CLOSED_LOOP_STEPS
    return tuple(sorted({min(chosen), max(chosen)}))


def _closed_loop(
    points: list[dict[str, Any]],
    models: Mapping[str, TrainedModel],
    out: str | Path,
    *,
    rig: str | Path,
    subtasks: int = CLOSED_LOOP_SUBTASKS,
    steps: Sequence[int] | None = None,
    workers: int | None,
    progress: bool,
) -> dict[str, Any]:
    """|ΔSR|, HFR, SR_imag (and their intervals) of every trained point on one protocol, real branches run once.

    ``steps``: the v1 step counts that run (``None``: all); every v2 point runs. The others get a note.
    """
    from pilworld.bench.paired import QUICK_CHECKPOINTS, protocol

    base = protocol(True)
    proto = PairedProtocol(base.tasks, QUICK_CHECKPOINTS, subtasks, base.rounds, base.seed)
    variants = []
    for p in points:
        if p.get("untrained") or p.get("skipped"):
            continue
        m = models[p["model"]]
        if m.family == "v1" and steps is not None and p["steps"] not in steps:
            p["closed_loop"] = f"not run (closed loop: v1 at {', '.join(map(str, steps))} step(s) only)"
            continue
        variants.append(
            ModelVariant(
                p["id"],
                p["id"],
                str(m.folder),  # explicit: "" would be the packaged v2
                adapter="none",
                steps=p["steps"] if m.family == "v1" else None,
                resize=m.family == "v1",
                role="point",
                trained_by=m.trained_by,
            )
        )
    if not variants:
        raise ValueError("speed-accuracy: no trained point to run in closed loop")
    results = evaluate_variants(variants, proto, out, rig=rig, workers=workers, progress=progress, single_step=False)
    for p in points:
        if p["id"] not in results:
            continue
        o = results[p["id"]]["metrics"]["overall"]
        ci = o.get("ci95") or {}
        p |= {k: o.get(k) for k in ("abs_delta_sr", "hfr", "sr_imag", "sr_real")}
        p["ci95"] = {k: ci[k] for k in ("abs_delta_sr", "hfr", "sr_imag") if k in ci}
        p["pairs"] = o.get("n_subtasks", proto.pairs)
    return {
        "pairs_per_point": proto.pairs,
        "tasks": list(proto.tasks),
        "checkpoints": list(proto.checkpoints),
        "subtasks": proto.subtasks,
        "rounds": proto.rounds,
        "v1_steps": "all" if steps is None else list(steps),
        "points": [v.name for v in variants],
        "out": str(out),
    }


# ---------------------------------------------------------------------- pilworld bench speed-accuracy

# The summary table, one row per point (pilworld/bench/output.py aligns it).
SPEED_ACCURACY_COLUMNS = (
    Column("point", 14, "id", align="<"),
    Column("params", 8, "params", lambda x: "—" if x is None else f"{x / 1e6:.2f}M"),
    Column("round ms", 10, "chunk_latency_ms", lambda x: num(x, 1)),
    Column("x realtime", 11, "realtime_factor", lambda x: num(x, 1)),
    Column("|ΔSR|", 7, "abs_delta_sr", pct),
    Column("HFR", 7, "hfr", lambda x: num(x, 3)),
    Column("SR_imag", 8, "sr_imag", pct),
    Column("head PSNR", 10, "psnr_head", num),
    Column("front", 5, "front", align="<", sep="  "),
    Column("", 0, "remark", align="<", sep=" "),
)


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        "--quick",
        action="store_true",
        help="steps 1,4,16, 24 held-out clips, 3 timed rounds; closed loop on 6 pairs, v1 at 1 step and v2 only",
    )
    add_rig(parser)
    parser.add_argument(
        "--steps", default="", help="comma-separated v1 sampling steps (default 1,2,4,8,16; quick 1,4,16)"
    )
    parser.add_argument("--clips", type=int, default=None, help="held-out clips per point (default 24 quick / 96)")
    parser.add_argument(
        "--repeats",
        type=int,
        default=None,
        help="timed imagined rounds per point; the median is reported (default 10, quick 3)",
    )
    parser.add_argument(
        "--subtasks", type=int, default=None, help="closed loop: subtasks per task × checkpoint (default 3, quick 1)"
    )
    parser.add_argument(
        "--out",
        type=Path,
        default=None,
        help="closed-loop run folders (default bench_runs/speed-accuracy-full, or -quick)",
    )
    parser.add_argument("--workers", type=int, default=None, help="judging processes (default: one per CPU)")
    parser.add_argument("--chart", type=Path, default=None, help="PNG to draw (default OUT/speed_accuracy.png)")
    add_json(parser)


def run(args: argparse.Namespace) -> int:
    """The sweep, its chart (``--chart``, default OUT/speed_accuracy.png), the points and the knee."""
    # Imported here: the chart needs matplotlib, which the other users of this module do not.
    from pilworld.bench.charts import speed_accuracy_chart

    try:
        steps = [int(s) for s in args.steps.split(",") if s.strip()] or None
    except ValueError:
        raise ValueError(f"--steps: expected comma-separated integers such as 1,2,4, got {args.steps!r}") from None
    if steps and min(steps) < 1:
        raise ValueError(f"--steps: expected integers >= 1, got {args.steps!r}")
    at_least_one(args, "clips", "repeats", "subtasks")
    out = run_folder(args, "speed-accuracy")
    r = run_speed_accuracy(
        rig=args.rig,
        quick=args.quick,
        steps=steps,
        clips=args.clips,
        repeats=args.repeats,
        subtasks=args.subtasks,
        out=out,
        workers=args.workers,
        progress=not args.json,
    )
    chart = speed_accuracy_chart(
        r["points"],
        r["front_ids"],
        args.chart or out / "speed_accuracy.png",
        knee=r["default"].get("id"),
        shipped=r["shipped_default"]["id"],
    )
    r["chart"] = str(chart)
    return emit(args, r, summary_lines(r))


def summary_lines(r: dict[str, Any]) -> list[str]:
    """The sweep in a line, every point's row, the knee and the shipped default, the single-step knee."""
    d, shipped, loop = r["default"], r["shipped_default"], r["closed_loop"]
    pairs = f"{loop['pairs_per_point']} closed-loop pairs per point" if "pairs_per_point" in loop else loop["skipped"]
    rows = [
        {
            **p,
            "front": "*" if p["id"] in r["front_ids"] else "",
            "remark": p.get("skipped") or p.get("untrained") or p.get("closed_loop") or "",
        }
        for p in r["points"]
    ]
    lines = [
        f"speed-accuracy ({'quick' if r['quick'] else 'full'}): {len(r['points'])} points, {pairs}, chart {r['chart']}",
        f"  latency: {r['latency']['measures']}",
        *table(SPEED_ACCURACY_COLUMNS, rows),
    ]
    if d.get("id") is None:
        lines.append(f"  knee: none ({d['none']})")
    else:
        lines.append(
            f"  knee: {d['id']} ({d['family']}{'' if d['preset'] == d['family'] else ' ' + d['preset']} "
            f"{d['size']}, {d['params']:,} parameters), "
            f"{d['chunk_latency_ms']:.1f} ms per round, |ΔSR| {pct(d['abs_delta_sr'])}, HFR {num(d['hfr'], 3)} "
            f"— {d['rule']}"
        )
        lines.append(f"  shipped default ({shipped['id']}): {shipped['verdict']}")
    single = r["single_step_knee"]
    lines.append(f"  single-step knee (head PSNR, for contrast): {single.get('id') or single.get('none')}")
    return lines
