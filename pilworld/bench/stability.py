"""``pilworld bench stability``: where world models fail — long horizons, failures, counterfactuals, bad inputs.

Five measurements of the shipped model on the simulated rig (layouts from seed 7,000,000, reserved):

1. **Horizon sweep** — one paired run with R = 20 rounds (real branches on the simulator), judged by the
   image-only judge. HFR at horizon R ∈ {1, 2, 5, 10, 20} is the mean over imagined episodes of
   min(t_h, T_R) / T_R with T_R = 1 + R·K frames (t_h: the automatic detector's first hallucination
   frame on the 20-round episode; the detector looks at most a few frames ahead, so a truncated episode
   would give the same t_h below T_R). Per-round error: head-view PSNR between the imagined and real
   frame at the end of each round, beside the same for the start frame held still ("frozen").
2. **Failure faithfulness** — on pairs whose real branch failed, the share whose imagined branch failed too
   (video models tend to "repair" failures); and the converse on real successes.
3. **Counterfactual divergence** — from each probe start, three different chunks (the policy's, "hold":
   stand still, "reverse": the policy's displacement mirrored) are executed both on the simulator and in
   the model for one round. For base vs hold and base vs reverse, the model's two futures differ by
   MSE_pred and the simulator's by MSE_real; ``ratio`` = MSE_pred / MSE_real (1: the model separates the
   futures as much as reality does; 0: it ignores the action).
4. **Calibration perturbed** — Γ drawn with the head camera's principal point shifted by 5, 10, 20 px
   (rig image pixels, diagonally), the policy's chunk: single-round head-view PSNR against the simulator.
5. **Out-of-distribution actions** — arm motions the training data never had ("fast": displacement ×3,
   each step's increment capped at 0.1 rad — about the joints' top speed,
   "jitter": N(0, 0.05 rad) per step, "offset": +0.3 rad on both shoulder lifts, ramped in), each executed
   in both branches through the same safety filter (which slows them to the joints' speed caps): single-
   round PSNR per view against the simulator, beside the policy's chunk.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
import torch
from numpy.typing import NDArray
from tqdm import tqdm

from hw_drivers.errors import SafetyViolationError
from pilworld.bench.common import machine_info
from pilworld.bench.variants import ModelVariant, PairedProtocol, evaluate_variants
from pilworld.types import LEFT_ARM, LEFT_GRIP, RIGHT_ARM, RIGHT_GRIP, ChunkSpec, Subtask
from pilworld.world_model.metrics import mse, psnr_from_mse

STABILITY_SEED0 = 7_000_000
HORIZONS = (1, 2, 5, 10, 20)
CAL_SHIFTS_PX = (0.0, 5.0, 10.0, 20.0)
HEAD = "cam_high"
QUICK_CHECKPOINTS = ("scripted_step_01k", "scripted_step_30k")

Chunk = NDArray[np.float32]


def _chw(a: NDArray[np.uint8]) -> torch.Tensor:
    """A decoded [..., H, W, 3] frame as the channels-first tensor the world-model metrics take."""
    return torch.from_numpy(np.ascontiguousarray(np.moveaxis(a, -1, -3)))


def _psnr(a: NDArray[np.uint8], b: NDArray[np.uint8]) -> float:
    """Whole-frame PSNR (dB) with the world-model metrics' definition and cap (identical frames)."""
    return float(psnr_from_mse(mse(_chw(a), _chw(b)).mean()))


def _mse(a: NDArray[np.uint8], b: NDArray[np.uint8]) -> float:
    return float(mse(_chw(a), _chw(b)).mean())


# ---------------------------------------------------------------------- 1 + 2: horizon and failures


def horizon_sweep(run: Path, rounds: int, frames_per_round: int) -> dict[str, Any]:
    """HFR at each horizon and per-round head-view PSNR from a judged R-round paired run."""
    from pilworld.data.reader import EpisodeStore
    from pilworld.metrics.pairs import load_pairs
    from pilworld.metrics.success import CHECKER_KIND

    store = EpisodeStore(run)
    paired = load_pairs(run, store)
    rows = []
    for h in (h for h in HORIZONS if h <= rounds):
        t_r = 1 + h * frames_per_round
        values = []
        for pair in paired.pairs:
            for o in paired.outcomes(pair.imagined):
                if o.judge_kind == CHECKER_KIND:
                    continue
                t_h = o.num_frames if o.first_hallucination_frame is None else o.first_hallucination_frame
                values.append(min(t_h, t_r) / t_r)
        rows.append({"rounds": h, "frames": t_r, "hfr": float(np.mean(values)) if values else None, "n": len(values)})
    per_round: list[dict[str, Any]] = []
    sums: dict[int, list[tuple[float, float]]] = {}
    for pair in paired.pairs:
        imag = store.frames(pair.imagined, HEAD)
        real = store.frames(pair.real, HEAD)
        n = min(len(imag), len(real))
        for r in range(1, rounds + 1):
            k = r * frames_per_round
            if k < n:
                sums.setdefault(r, []).append((_psnr(imag[k], real[k]), _psnr(real[0], real[k])))
    for r, vals in sorted(sums.items()):
        per_round.append(
            {
                "round": r,
                "psnr_head": float(np.mean([v[0] for v in vals])),
                "psnr_head_frozen": float(np.mean([v[1] for v in vals])),
                "n": len(vals),
            }
        )
    return {"rows": rows, "per_round": per_round, "pairs": len(paired.pairs), "run": str(run)}


# ---------------------------------------------------------------------- 3-5: single-round probes


GRIPS = (LEFT_GRIP, RIGHT_GRIP)
JITTER_RAD = 0.05
# At most the joints' speed cap per control step (π rad/s at 30 Hz ≈ 0.105 rad): the filter slows a faster
# target to that cap, the gap to the next target then grows, and past 0.35 rad the filter refuses.
FAST_STEP_RAD = 0.1
EXECUTED_STEPS = ChunkSpec().executed_steps  # K·Δ = 45 of the policy's H_π = 50 rows are executed


def _arms_only(chunk: NDArray[np.floating], base: Chunk) -> Chunk:
    """``chunk`` with the grippers' columns back to the policy's (the probes change arm motion only)."""
    out = np.asarray(chunk, dtype=np.float32).copy()
    out[:, GRIPS] = base[:, GRIPS]
    return out


def _hold(base: Chunk, state: Chunk) -> Chunk:
    return _arms_only(np.repeat(state[None], base.shape[0], axis=0), base)


def _reverse(base: Chunk, state: Chunk) -> Chunk:
    return _arms_only(2.0 * state[None] - base, base)


def _fast(base: Chunk, state: Chunk) -> Chunk:
    """The displacement ×3, each step's increment limited to FAST_STEP_RAD (the filter refuses jumps > 0.35)."""
    want = state[None] + 3.0 * (base - state[None])
    out = np.empty_like(want)
    prev = state.astype(np.float64)
    for i, row in enumerate(want):
        prev = prev + np.clip(row - prev, -FAST_STEP_RAD, FAST_STEP_RAD)
        out[i] = prev
    return _arms_only(out, base)


def _jitter(base: Chunk, state: Chunk, rng: np.random.Generator) -> Chunk:
    # Clipped so consecutive targets stay inside the safety filter's per-step cap (0.35 rad).
    noise = np.clip(rng.normal(0.0, JITTER_RAD, size=base.shape), -2 * JITTER_RAD, 2 * JITTER_RAD).astype(np.float32)
    noise[:, GRIPS] = 0.0  # the grippers keep the policy's command
    return (base + noise).astype(np.float32)


def _offset(base: Chunk, state: Chunk) -> Chunk:
    """+0.3 rad on both shoulder lifts, ramped in over the chunk (a jump would be refused by the safety filter)."""
    out = base.copy()
    # Full 0.3 rad by the last executed step (K·Δ of the H_π rows run), then held.
    ramp = 0.3 * np.minimum(np.arange(1, base.shape[0] + 1, dtype=np.float32) / EXECUTED_STEPS, 1.0)
    out[:, LEFT_ARM.start + 1] += ramp
    out[:, RIGHT_ARM.start + 1] += ramp
    return out


def shifted_camera(camera: Any, shift_px: float) -> Any:
    """The camera with its principal point moved ``shift_px`` pixels diagonally (a calibration error)."""
    from calib.camera_model import CameraModel

    K = np.array(camera.K, dtype=np.float64)
    d = shift_px / math.sqrt(2.0)
    K[0, 2] += d
    K[1, 2] += d
    return CameraModel(K, camera.dist, camera.T_cam_base, camera.width, camera.height, camera.name)


def probe(
    *,
    rig: str | Path,
    tasks: tuple[str, ...],
    checkpoints: tuple[str, ...],
    starts: int,
    seed0: int = STABILITY_SEED0,
    progress: bool = True,
) -> dict[str, Any]:
    """Counterfactual, calibration and OOD probes: one round from each start, on the simulator and in the model."""
    from hw_drivers.sim.tasks import make_task
    from pilworld.config.rig import RigConfig
    from pilworld.control_video.gamma import ControlVideo
    from pilworld.envs import ImaginedEnv, RobotEnv, SafetyFilter
    from pilworld.paired.runner import PairedConfig, load_model, plan_subtasks
    from pilworld.paired.stations import SimStation
    from pilworld.policies.registry import make_policy

    rig_cfg = RigConfig.load(rig)
    spec = ChunkSpec(rounds=1)
    views = list(rig_cfg.cameras)
    kinds: dict[str, Callable[[Chunk, Chunk], Chunk]] = {
        "policy": lambda b, s: b,
        "hold": _hold,
        "reverse": _reverse,
        "fast": _fast,
        "offset": _offset,
    }
    gammas = {
        shift: ControlVideo(rig_cfg.kinematics, shifted_camera(rig_cfg.head_camera_model, shift), spec)
        for shift in CAL_SHIFTS_PX
    }
    records: list[dict[str, Any]] = []
    refused: list[dict[str, Any]] = []
    plan = []
    for task in tasks:
        t = make_task(task)
        plan += plan_subtasks(task, starts, seed0, checkpoints, t.num_subtasks, t.instruction)
    cfg0 = PairedConfig(rig=str(rig), task=",".join(tasks), checkpoints=list(checkpoints), subtasks=1, out="")
    models = {task: load_model(cfg0, rig_cfg, task)[0] for task in tasks}
    policies = {c: make_policy(c, rig_cfg, spec) for c in checkpoints}
    rng = np.random.default_rng(seed0)
    station = SimStation(rig, tasks[0])
    with station:
        for pair in tqdm(plan, desc="probes", unit="start", disable=not progress):
            sub: Subtask = pair.subtask
            start = station.start(sub, pair.checkpoint, spec)
            policy = policies[pair.checkpoint]
            policy.reset(seed=pair.seed)
            state = np.asarray(start.observation.state, dtype=np.float32)
            base = np.asarray(policy.infer(start.observation, sub.instruction), dtype=np.float32)
            chunks = {k: f(base, state) for k, f in kinds.items()}
            chunks["jitter"] = _jitter(base, state, rng)
            real: dict[str, dict[str, NDArray[np.uint8]]] = {}
            imag: dict[str, dict[str, NDArray[np.uint8]]] = {}
            for kind, chunk in chunks.items():
                start = station.start(sub, pair.checkpoint, spec)  # the same start for every chunk
                env = RobotEnv(station.robot, spec)
                env.reset(start)
                try:
                    seg = env.step(chunk)
                except SafetyViolationError as exc:  # counted; the probe goes on without this chunk
                    refused.append({"pair": pair.pair_id, "kind": kind, "error": str(exc)})
                    continue
                real[kind] = {v: np.stack([o.images[v] for o in seg.observations]) for v in views}
                for shift, gamma in gammas.items():
                    if shift and kind != "policy":
                        continue
                    ienv = ImaginedEnv(
                        models[sub.task],
                        gamma,
                        spec,
                        control_rate_hz=rig_cfg.control_rate_hz,
                        seed=pair.seed,
                        safety=SafetyFilter(station.robot.spec),
                    )
                    ienv.reset(start)
                    iseg = ienv.step(chunk)
                    key = kind if not shift else f"policy@{shift:g}px"
                    imag[key] = {v: np.stack([o.images[v] for o in iseg.observations]) for v in views}
            if not {"policy", "hold", "reverse"} <= set(real):
                continue  # no counterfactual without the policy's chunk and both alternatives
            rec: dict[str, Any] = {"pair": pair.pair_id, "task": sub.task}
            for key, frames in imag.items():
                kind = key.split("@")[0]
                rec[f"psnr:{key}"] = {v: _psnr(frames[v], real[kind][v]) for v in views}
            still = {v: np.repeat(start.observation.images[v][None], spec.frames, axis=0) for v in views}
            rec["psnr:frozen"] = {v: _psnr(still[v], real["policy"][v]) for v in views}
            for alt in ("hold", "reverse"):
                rec[f"div:{alt}"] = {
                    v: {"pred": _mse(imag["policy"][v], imag[alt][v]), "real": _mse(real["policy"][v], real[alt][v])}
                    for v in views
                }
            records.append(rec)
    return {**_summarize_probes(records, views), "refused": refused}


def _mean(xs: list[float]) -> float | None:
    return float(np.mean(xs)) if xs else None


def _summarize_probes(records: list[dict[str, Any]], views: list[str]) -> dict[str, Any]:
    counterfactual = []
    for alt in ("hold", "reverse"):
        row: dict[str, Any] = {"alternative": alt}
        for v in views:
            pred = [r[f"div:{alt}"][v]["pred"] for r in records]
            real = [r[f"div:{alt}"][v]["real"] for r in records]
            ratios = [p / q for p, q in zip(pred, real, strict=True) if q > 1e-9]
            row[v] = {
                "mse_pred": _mean(pred),
                "mse_real": _mean(real),
                "ratio_median": float(np.median(ratios)) if ratios else None,
                "distinct_share": float(np.mean([p > 0.0 for p in pred])) if pred else None,
            }
        counterfactual.append(row)
    calibration = []
    for shift in CAL_SHIFTS_PX:
        key = "psnr:policy" if not shift else f"psnr:policy@{shift:g}px"
        calibration.append({"shift_px": shift, "psnr_head": _mean([r[key][HEAD] for r in records]), "n": len(records)})
    base_head = calibration[0]["psnr_head"]
    for row in calibration:
        row["delta_db"] = None if base_head is None or row["psnr_head"] is None else row["psnr_head"] - base_head
    ood = []
    for kind in ("policy", "fast", "jitter", "offset"):
        have = [r for r in records if f"psnr:{kind}" in r]
        row = {"kind": kind, "psnr_head": _mean([r[f"psnr:{kind}"][HEAD] for r in have]), "n": len(have)}
        row["per_view"] = {v: _mean([r[f"psnr:{kind}"][v] for r in have]) for v in views}
        ood.append(row)
    frozen = {v: _mean([r["psnr:frozen"][v] for r in records]) for v in views}
    return {
        "starts": len(records),
        "counterfactual": {"rows": counterfactual},
        "calibration": {"rows": calibration},
        "ood_actions": {"rows": ood, "frozen_per_view": frozen},
    }


# ---------------------------------------------------------------------- the bench


def run_stability(
    *,
    rig: str | Path,
    quick: bool = False,
    out: str | Path = "bench_runs/stability",
    subtasks: int | None = None,
    starts: int | None = None,
    workers: int | None = None,
    progress: bool = True,
) -> dict[str, Any]:
    from hw_drivers.sim.tasks import TASK_NAMES
    from pilworld.bench.paired import failure_faithfulness

    t0 = time.monotonic()
    rounds = max(HORIZONS)
    tasks = tuple(TASK_NAMES)
    proto = PairedProtocol(tasks, QUICK_CHECKPOINTS, subtasks or (1 if quick else 5), rounds, STABILITY_SEED0)
    shipped = ModelVariant("pilworld", "PiL-World (shipped)", role="shipped")
    results = evaluate_variants(
        [shipped], proto, Path(out) / "horizon", rig=rig, workers=workers, progress=progress, single_step=False
    )
    run = Path(results["pilworld"]["out"])
    horizon = horizon_sweep(run, rounds, ChunkSpec().frames)
    horizon["protocol"] = {
        "tasks": list(tasks),
        "checkpoints": list(proto.checkpoints),
        "subtasks": proto.subtasks,
        "rounds": rounds,
        "seed0": proto.seed,
    }
    faith = failure_faithfulness(str(run))
    probes = probe(
        rig=rig,
        tasks=tasks,
        checkpoints=QUICK_CHECKPOINTS,
        starts=starts or (1 if quick else 4),
        seed0=STABILITY_SEED0 + 500,
        progress=progress,
    )
    return {
        "bench": "stability",
        "quick": quick,
        "horizon": horizon,
        "failure_faithfulness": faith,
        **probes,
        "machine": machine_info(),
        "wall_s": round(time.monotonic() - t0, 1),
    }
