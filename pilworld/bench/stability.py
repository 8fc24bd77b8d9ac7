"""``pilworld bench stability``: where world models fail — long horizons, failures, counterfactuals, bad inputs.

Several world models side by side (default: the shipped v2 ``pilworld`` and the paper-faithful
``v2_paper_gamma``, names from :mod:`pilworld.bench.variants`) on the simulated rig:

1. **Horizon sweep** — one paired protocol with R = 20 rounds (layouts from seed 7,000,000, reserved),
   every model on the same pairs (:func:`~pilworld.bench.variants.evaluate_variants`: the real branches
   run once and are shared), judged by the image-only judge. HFR at horizon R ∈ {1, 2, 5, 10, 20} is the
   mean over imagined episodes of min(t_h, T_R) / T_R with T_R = 1 + R·K frames (t_h: the automatic
   detector's first hallucination frame on the 20-round episode; the detector looks at most a few frames
   ahead, so a truncated episode would give the same t_h below T_R). Per-round error: head-view PSNR
   between the imagined and real frame at the end of each round, beside the start frame held still
   ("frozen").
2. **Failure faithfulness** — on pairs whose real branch failed, the share whose imagined branch failed
   too (video models tend to "repair" failures); and the converse on real successes.

The probes start from 3 tasks × 2 checkpoints × ``starts`` subtasks (layouts from seed 7,000,500). Each
chunk is executed on the simulator once per start and imagined by every model from the same start,
through the same safety filter (a refused chunk is listed in ``refused`` and left out):

3. **Counterfactual divergence** — the policy's chunk, "hold" (stand still) and "reverse" (the policy's
   displacement mirrored), one round each. For policy vs hold and policy vs reverse, the model's two
   futures differ by MSE_pred and the simulator's by MSE_real; ``ratio`` = median over starts of
   MSE_pred / MSE_real (1: the model separates the futures as much as reality does; 0: it ignores the
   action).
4. **Calibration and mount errors** — the policy's chunk imagined with a wrong calibration *given to the
   model* (the simulator keeps the true rig): the head camera's principal point moved 5, 10, 20 px
   (diagonally, of 128); the head camera's extrinsics off by (2 mm, 0.2°), (5 mm, 0.5°), (10 mm, 1°); each
   wrist camera's mount off by (2 mm, 0.5°), (5 mm, 1°) (directions from
   :func:`~pilworld.control_video.probes.perturbed_cameras` with seed ``ERROR_SEED``). A model that
   composites the rig's geometry (v2, ``bind_rig``) is bound to the wrong rig
   (:func:`~pilworld.control_video.probes.perturbed_rig`: its layers, tracked objects and their drawing
   use the wrong cameras); every model's control video Γ (the markers) is drawn through the wrong head
   camera. A model without ``bind_rig`` gets only the Γ change (wrist errors do not reach it).
5. **Robot-model mismatch** — the same, with the robot model rendered by the model's layers wrong: link
   radii ×0.8, ×1.2, every robot geom coloured (0.8, 0.3, 0.3, 1) (models with ``bind_rig`` only).
   For 4 and 5: single-round PSNR per view against the simulator, and its change from the right rig.
6. **Out-of-distribution actions** — arm motions the training data never had ("fast": displacement ×3,
   each step's increment capped at 0.1 rad — about the joints' top speed, "jitter": N(0, 0.05 rad) per
   step, "offset": +0.3 rad on both shoulder lifts, ramped in), each executed in both branches through the
   same safety filter (which slows them to the joints' speed caps): single-round PSNR per view against
   the simulator, beside the policy's chunk.
7. **Action shuffle** (cross-episode) — for ``SHUFFLE_ROUNDS`` = 2 rounds, another episode's chunks
   transplanted onto this start: the donor is the same task, checkpoint and subtask on layout seed
   + ``DONOR_SEED_OFFSET`` (its policy's first chunk, then the chunk it computes after that chunk ran on
   the simulator); arm columns = this branch's state + the donor chunk's displacement from the donor's
   state, grippers = the donor's commands. Executed on the simulator and imagined by every model, beside
   the policy's own two chunks (the second computed from the simulator's frame after the first, fed to
   both). Per view: divergence (MSE between the own and the shuffled futures, model vs simulator: the
   median ratio and the share of starts where the model's futures differ at all — "a different
   future"); consistency (PSNR of the model's shuffled future against the simulator's, beside the same
   for the own chunks — "a consistent future"); determinism (the shuffled chunks imagined twice with the
   same seed give identical frames).

The probes run in a spawned process of their own beside the horizon runs (``workers=1``: one after the
other); every figure is the same either way.

Seeds: horizon layouts from ``STABILITY_SEED0`` = 7,000,000, probe layouts from ``PROBE_SEED0`` =
7,000,500 (the policy and model seed of each start is its pair seed), donors at + ``DONOR_SEED_OFFSET``,
the jitter noise from ``numpy.random.default_rng(PROBE_SEED0)`` in start order, the directions of the
camera errors from ``ERROR_SEED``.
"""

from __future__ import annotations

import concurrent.futures
import multiprocessing as mp
import tempfile
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
import torch
from numpy.typing import NDArray
from tqdm import tqdm

from hw_drivers.errors import SafetyViolationError
from pilworld.bench.common import machine_info
from pilworld.bench.variants import (
    ModelVariant,
    PairedProtocol,
    evaluate_variants,
    standard_variants,
    v2_variants,
)
from pilworld.types import LEFT_ARM, LEFT_GRIP, RIGHT_ARM, RIGHT_GRIP, ChunkSpec, Subtask
from pilworld.world_model.metrics import mse, psnr_from_mse

if TYPE_CHECKING:
    from pilworld.config.rig import RigConfig
    from pilworld.control_video.robot_model import RobotModel

STABILITY_SEED0 = 7_000_000
PROBE_SEED0 = STABILITY_SEED0 + 500
DONOR_SEED_OFFSET = 250  # the action shuffle's donor: the same subtask on layout seed + this
ERROR_SEED = 0  # directions and axes of the camera errors (pilworld.control_video.probes)
DEFAULT_MODELS = ("pilworld", "v2_paper_gamma")
HORIZONS = (1, 2, 5, 10, 20)
CAL_SHIFTS_PX = (0.0, 5.0, 10.0, 20.0)
HEAD_ERRORS = ((0.002, 0.2), (0.005, 0.5), (0.010, 1.0))  # (translation m, rotation deg) of the head camera
WRIST_ERRORS = ((0.002, 0.5), (0.005, 1.0))  # of each wrist camera's mount
ROBOT_ERRORS: tuple[tuple[float, tuple[float, float, float, float] | None], ...] = (
    (0.8, None),
    (1.2, None),
    (1.0, (0.8, 0.3, 0.3, 1.0)),
)  # (radius scale, colour) of the robot model
ERROR_KINDS = ("principal_point", "head_extrinsics", "wrist_mount", "robot_model")
CALIBRATION_KINDS = ERROR_KINDS[:3]  # the JSON's "calibration"; "robot_model" is its "robot_mismatch"
SHUFFLE_ROUNDS = 2
HEAD = "cam_high"
QUICK_CHECKPOINTS = ("scripted_step_01k", "scripted_step_30k")

Chunk = NDArray[np.float32]
Frames = dict[str, NDArray[np.uint8]]  # view → (T, H, W, 3)


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


# ---------------------------------------------------------------------- 3-7: the probes' chunks


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


def transplant(donor: NDArray[np.floating], donor_state: NDArray[np.floating], state: NDArray[np.floating]) -> Chunk:
    """Another episode's chunk on this branch: the arms move from ``state`` by the donor chunk's displacement
    from ``donor_state`` (the donor's state when its policy computed the chunk); the grippers get the donor's
    commands."""
    d = np.asarray(donor, dtype=np.float64)
    s0 = np.asarray(donor_state, dtype=np.float64)
    s = np.asarray(state, dtype=np.float64)
    if d.ndim != 2 or s0.shape != (d.shape[1],) or s.shape != (d.shape[1],):
        raise ValueError(
            f"transplant: expected a chunk (H, D) and two states (D,), got {d.shape}, {s0.shape}, {s.shape}"
        )
    out = s[None] + (d - s0[None])
    out[:, GRIPS] = d[:, GRIPS]
    return out.astype(np.float32)


# ---------------------------------------------------------------------- 4-5: the wrong rigs


@dataclass(frozen=True)
class RigError:
    """One wrong calibration or robot model given to the models (the simulator keeps the true rig)."""

    kind: str  # "principal_point" | "head_extrinsics" | "wrist_mount" | "robot_model"
    shift_px: float = 0.0  # principal_point
    translation_m: float = 0.0  # head_extrinsics, wrist_mount
    rotation_deg: float = 0.0
    radius_scale: float = 1.0  # robot_model
    rgba: tuple[float, float, float, float] | None = None

    def __post_init__(self) -> None:
        if self.kind not in ERROR_KINDS:
            raise ValueError(f"kind: expected one of {', '.join(ERROR_KINDS)}, got {self.kind!r}")

    @property
    def cameras(self) -> bool:
        return self.kind != "robot_model"

    @property
    def key(self) -> str:
        if self.kind == "principal_point":
            return f"pp{self.shift_px:g}px"
        if self.kind in ("head_extrinsics", "wrist_mount"):
            return f"{self.kind.split('_')[0]}{1000 * self.translation_m:g}mm{self.rotation_deg:g}deg"
        if self.rgba is not None:
            return "rgba" + ",".join(f"{c:g}" for c in self.rgba)
        return f"radius{self.radius_scale:g}"

    @property
    def label(self) -> str:
        if self.kind == "principal_point":
            return f"head principal point +{self.shift_px:g} px"
        if self.kind == "head_extrinsics":
            return f"head camera extrinsics {1000 * self.translation_m:g} mm, {self.rotation_deg:g}°"
        if self.kind == "wrist_mount":
            return f"wrist camera mounts {1000 * self.translation_m:g} mm, {self.rotation_deg:g}°"
        if self.rgba is not None:
            return "robot colour (" + ", ".join(f"{c:g}" for c in self.rgba) + ")"
        return f"robot link radii ×{self.radius_scale:g}"

    @property
    def params(self) -> dict[str, Any]:
        """The error's size for the JSON (with the seed of a camera error's directions)."""
        if self.kind == "principal_point":
            return {"shift_px": self.shift_px}
        if self.kind == "robot_model":
            return {"radius_scale": self.radius_scale, "rgba": None if self.rgba is None else list(self.rgba)}
        return {"translation_m": self.translation_m, "rotation_deg": self.rotation_deg, "seed": ERROR_SEED}

    @property
    def moves_head(self) -> bool:
        """Whether the head camera — so Γ's markers — is wrong: all of it that reaches a model without ``bind_rig``."""
        return self.kind in ("principal_point", "head_extrinsics")

    def rig(self, rig: RigConfig, folder: Path) -> RigConfig:
        """The rig config the models are given (a camera error's calibration files under ``folder/key``)."""
        from pilworld.control_video.probes import perturbed_rig

        if not self.cameras:
            return rig
        head, wrist = self.kind == "head_extrinsics", self.kind == "wrist_mount"
        return perturbed_rig(
            rig,
            folder / self.key,
            principal_shift_px=self.shift_px,
            head_translation_m=self.translation_m if head else 0.0,
            head_rotation_deg=self.rotation_deg if head else 0.0,
            wrist_translation_m=self.translation_m if wrist else 0.0,
            wrist_rotation_deg=self.rotation_deg if wrist else 0.0,
            seed=ERROR_SEED,
        )

    def robot(self, rig: RigConfig) -> RobotModel | None:
        """The robot model the models render (None: the rig's own)."""
        from pilworld.control_video.probes import mismatched_robot

        return None if self.cameras else mismatched_robot(rig, radius_scale=self.radius_scale, rgba=self.rgba)

    def to_json(self) -> dict[str, Any]:
        return {"kind": self.kind, "key": self.key, "label": self.label, "params": self.params}


def rig_errors() -> list[RigError]:
    """Calibration errors (principal point, head extrinsics, wrist mounts), then robot-model errors."""
    return [
        *(RigError("principal_point", shift_px=s) for s in CAL_SHIFTS_PX if s),
        *(RigError("head_extrinsics", translation_m=t, rotation_deg=a) for t, a in HEAD_ERRORS),
        *(RigError("wrist_mount", translation_m=t, rotation_deg=a) for t, a in WRIST_ERRORS),
        *(RigError("robot_model", radius_scale=s, rgba=c) for s, c in ROBOT_ERRORS),
    ]


# ---------------------------------------------------------------------- the models


def known_models() -> dict[str, ModelVariant]:
    """The variants the bench can run, by name (pilworld.bench.variants)."""
    return {v.name: v for v in standard_variants() + v2_variants()}


def resolve_models(names: Sequence[str] | None = None) -> list[ModelVariant]:
    """The variants named (default ``DEFAULT_MODELS``); an unknown or repeated name is a ``ValueError``."""
    wanted = list(DEFAULT_MODELS if names is None else names)
    known = known_models()
    if not wanted:
        raise ValueError(f"models: expected at least one of {', '.join(known)}")
    unknown = [n for n in wanted if n not in known]
    if unknown:
        raise ValueError(f"models: unknown {', '.join(unknown)}; known: {', '.join(known)}")
    if len(set(wanted)) != len(wanted):
        raise ValueError(f"models: listed twice: {', '.join(wanted)}")
    return [known[n] for n in wanted]


class _Imaginer:
    """One variant's world models for the probes: per task (one for all tasks without task adapters), given the
    right rig or a wrong one (``wrong``: error key → (rig config, robot model or None)), each loaded once."""

    def __init__(
        self, variant: ModelVariant, rig_path: str | Path, rig: Any, wrong: dict[str, tuple[Any, Any]]
    ) -> None:
        variant.check()
        self.variant = variant
        self._rig_path, self._rig, self._wrong = rig_path, rig, wrong
        self._models: dict[tuple[str, str], Any] = {}
        self.binds_rig: bool | None = None  # known once a model is loaded

    def _load(self, task: str) -> Any:
        from pilworld.paired.runner import PairedConfig, load_model

        v = self.variant
        cfg = PairedConfig(
            rig=str(self._rig_path),
            task=task,
            checkpoints=list(QUICK_CHECKPOINTS),
            subtasks=1,
            out="",
            world_model=v.world_model,
            adapter=v.adapter,
            steps=v.steps,
            history=v.history,
            resize=v.resize,
        )
        model = load_model(cfg, self._rig, task)[0]
        self.binds_rig = callable(getattr(model, "bind_rig", None))
        return model

    def model(self, task: str, error: RigError | None = None) -> Any:
        """The model of ``task`` given the right rig (``error`` None) or the wrong one."""
        scope = "" if self.variant.adapter == "none" else task
        key = (scope, "" if error is None else error.key)
        if key not in self._models:
            if error is None:
                self._models[key] = self._load(task)
            else:
                model = self.model(task)  # the right rig's first: whether the model binds a rig at all
                if self.binds_rig:
                    model = self._load(task)
                    rig, robot = self._wrong[error.key]
                    if robot is None:
                        model.bind_rig(rig)
                    else:
                        model.bind_rig(rig, robot=robot)
                self._models[key] = model  # without bind_rig: the same model, only its control video Γ is wrong
        return self._models[key]

    def applies(self, error: RigError) -> bool:
        """Whether ``error`` reaches the model (one without ``bind_rig`` sees only Γ's head camera)."""
        if self.binds_rig is None:
            raise RuntimeError("applies: load a model first")
        return self.binds_rig or error.moves_head


def _frames(segments: Sequence[Any], views: Sequence[str]) -> Frames:
    """The frames of consecutive segments per view, the rounds one after the other."""
    return {v: np.stack([o.images[v] for seg in segments for o in seg.observations]) for v in views}


# ---------------------------------------------------------------------- 3-7: the probes


ChunkMaker = Callable[[Any], Chunk]  # the observation a round starts from → its chunk


class _Prober:
    """The probes of one start after another: each chunk executed once on the simulator, imagined by each model."""

    def __init__(
        self,
        station: Any,
        rig: str | Path,
        rig_cfg: Any,
        variants: Sequence[ModelVariant],
        checkpoints: tuple[str, ...],
        seed0: int,
        folder: Path,
    ) -> None:
        from pilworld.control_video.gamma import ControlVideo
        from pilworld.policies.registry import make_policy

        self.station = station
        self.rig_cfg = rig_cfg
        self.spec = ChunkSpec(rounds=1)
        self.views = list(rig_cfg.cameras)
        self.errors = rig_errors()
        self.policies = {c: make_policy(c, rig_cfg, self.spec) for c in checkpoints}
        self.rng = np.random.default_rng(seed0)
        wrong = {e.key: (e.rig(rig_cfg, folder), e.robot(rig_cfg)) for e in self.errors}
        self.imaginers = [_Imaginer(v, rig, rig_cfg, wrong) for v in variants]
        self.gammas: dict[str, Any] = {"": ControlVideo.from_rig(rig_cfg, self.spec)}
        for key, (given, _) in wrong.items():  # Γ's markers drawn through the head camera the models are given
            self.gammas[key] = ControlVideo.from_rig(given, self.spec)
        self.refused: list[dict[str, Any]] = []

    def sim(self, pair: Any, subtask: Subtask, kind: str, chunks: Sequence[Chunk | ChunkMaker]) -> list[Any]:
        """Rounds on the simulator from a fresh start of ``subtask`` (a chunk, or a function of the observation
        its round starts from), as many as the safety filter accepts (a refusal is listed under ``kind``)."""
        from pilworld.envs import RobotEnv

        env = RobotEnv(self.station.robot, self.spec, pace=self.station.pace)  # the simulator: no wall-clock pacing
        obs = env.reset(self.station.start(subtask, pair.checkpoint, self.spec))
        segments: list[Any] = []
        for i, chunk in enumerate(chunks):
            try:
                segments.append(env.step(chunk(obs) if callable(chunk) else chunk))
            except SafetyViolationError as exc:  # counted; the probe goes on without this chunk
                self.refused.append({"pair": pair.pair_id, "kind": kind, "round": i + 1, "error": str(exc)})
                break
            obs = segments[-1].last
        return segments

    def imagine(
        self, im: _Imaginer, pair: Any, start: Any, chunks: Sequence[Chunk], kind: str, error: RigError | None = None
    ) -> Frames | None:
        """``chunks`` imagined round after round from ``start`` (None: the safety filter refused one)."""
        from pilworld.envs import ImaginedEnv, SafetyFilter

        env = ImaginedEnv(
            im.model(pair.subtask.task, error),
            self.gammas["" if error is None else error.key],
            self.spec,
            control_rate_hz=self.rig_cfg.control_rate_hz,
            seed=pair.seed,
            steps=im.variant.steps,
            safety=SafetyFilter(self.station.robot.spec),
        )
        env.reset(start)
        try:
            return _frames([env.step(c) for c in chunks], self.views)
        except SafetyViolationError as exc:
            self.refused.append({"pair": pair.pair_id, "kind": kind, "model": im.variant.name, "error": str(exc)})
            return None

    def run(self, pair: Any) -> dict[str, dict[str, Any]]:
        """One start's record per model (none: the policy's chunk or a counterfactual alternative was refused)."""
        from pilworld.paired.runner import PairedSubtask

        sub: Subtask = pair.subtask
        views = self.views
        policy = self.policies[pair.checkpoint]
        start = self.station.start(sub, pair.checkpoint, self.spec)
        state = np.asarray(start.observation.state, dtype=np.float32)
        policy.reset(seed=pair.seed)
        base = np.asarray(policy.infer(start.observation, sub.instruction), dtype=np.float32)
        chunks = {"hold": _hold(base, state), "reverse": _reverse(base, state), "fast": _fast(base, state)}
        chunks["jitter"] = _jitter(base, state, self.rng)
        chunks["offset"] = _offset(base, state)

        def policy_chunk(obs: Any) -> Chunk:
            return np.asarray(policy.infer(obs, sub.instruction), dtype=np.float32)

        # The policy's chunk, then (the action shuffle's reference) its next chunks from the simulator's frames.
        own: list[Chunk] = [base]

        def own_chunk(obs: Any) -> Chunk:
            own.append(policy_chunk(obs))
            return own[-1]

        real: dict[str, Frames] = {}
        segments = self.sim(pair, sub, "policy", [base, *[own_chunk] * (SHUFFLE_ROUNDS - 1)])
        if not segments:
            return {}
        real["policy"] = _frames(segments[:1], views)
        for kind, chunk in chunks.items():
            got = self.sim(pair, sub, kind, [chunk])
            if got:
                real[kind] = _frames(got, views)
        if not {"hold", "reverse"} <= set(real):
            return {}
        shuffled: list[Chunk] = []
        if len(segments) == SHUFFLE_ROUNDS:
            real["own"] = _frames(segments, views)
            # The donor: the same subtask on another layout. Its rounds but the last run on the simulator; its last
            # chunk comes from where they leave it. Then its chunks transplanted onto this start.
            donor = PairedSubtask(
                pair.checkpoint,
                Subtask(task=sub.task, index=sub.index, instruction=sub.instruction, seed=sub.seed + DONOR_SEED_OFFSET),
            )
            donated: list[tuple[Chunk, Chunk]] = []  # (chunk, the donor's state it was computed at)

            def donor_chunk(obs: Any) -> Chunk:
                donated.append((policy_chunk(obs), np.asarray(obs.state, dtype=np.float32)))
                return donated[-1][0]

            def shuffled_chunk(obs: Any) -> Chunk:
                chunk, at = donated[len(shuffled)]
                shuffled.append(transplant(chunk, at, np.asarray(obs.state, dtype=np.float32)))
                return shuffled[-1]

            policy.reset(seed=donor.seed)
            ran = self.sim(pair, donor.subtask, "donor", [donor_chunk] * (SHUFFLE_ROUNDS - 1))
            if len(ran) == SHUFFLE_ROUNDS - 1:
                last = (
                    ran[-1].last if ran else self.station.start(donor.subtask, pair.checkpoint, self.spec).observation
                )
                donor_chunk(last)
                got = self.sim(pair, sub, "shuffle", [shuffled_chunk] * SHUFFLE_ROUNDS)
                if len(got) == SHUFFLE_ROUNDS:
                    real["shuffle"] = _frames(got, views)
        out: dict[str, dict[str, Any]] = {}
        for im in self.imaginers:
            rec = self._record(im, pair, start, own, chunks, shuffled, real)
            if rec is not None:
                out[im.variant.name] = rec
        return out

    def _record(
        self,
        im: _Imaginer,
        pair: Any,
        start: Any,
        own: list[Chunk],
        chunks: dict[str, Chunk],
        shuffled: list[Chunk],
        real: dict[str, Frames],
    ) -> dict[str, Any] | None:
        views, K = self.views, self.spec.frames
        imag_own = self.imagine(im, pair, start, own if "own" in real else own[:1], "policy")
        if imag_own is None:
            return None
        imag: dict[str, Frames] = {"policy": {v: f[:K] for v, f in imag_own.items()}}
        for kind, chunk in chunks.items():
            if kind in real:
                got = self.imagine(im, pair, start, [chunk], kind)
                if got is not None:
                    imag[kind] = got
        if not {"hold", "reverse"} <= set(imag):
            return None
        rec: dict[str, Any] = {"pair": pair.pair_id, "task": pair.subtask.task}
        for kind, frames in imag.items():
            rec[f"psnr:{kind}"] = {v: _psnr(frames[v], real[kind][v]) for v in views}
        still = {v: np.repeat(start.observation.images[v][None], K, axis=0) for v in views}
        rec["psnr:frozen"] = {v: _psnr(still[v], real["policy"][v]) for v in views}
        for alt in ("hold", "reverse"):
            rec[f"div:{alt}"] = {
                v: {"pred": _mse(imag["policy"][v], imag[alt][v]), "real": _mse(real["policy"][v], real[alt][v])}
                for v in views
            }
        for error in self.errors:
            if im.applies(error):
                wrong = self.imagine(im, pair, start, own[:1], f"policy@{error.key}", error)
                if wrong is not None:
                    rec[f"psnr:err:{error.key}"] = {v: _psnr(wrong[v], real["policy"][v]) for v in views}
        if "shuffle" in real:
            first = self.imagine(im, pair, start, shuffled, "shuffle")
            again = self.imagine(im, pair, start, shuffled, "shuffle")
            if first is not None and again is not None:
                held = {v: np.repeat(start.observation.images[v][None], len(first[v]), axis=0) for v in views}
                rec["shuffle"] = {
                    "div": {
                        v: {"pred": _mse(imag_own[v], first[v]), "real": _mse(real["own"][v], real["shuffle"][v])}
                        for v in views
                    },
                    "psnr": {
                        v: {
                            "shuffled": _psnr(first[v], real["shuffle"][v]),
                            "own": _psnr(imag_own[v], real["own"][v]),
                            "frozen": _psnr(held[v], real["shuffle"][v]),
                        }
                        for v in views
                    },
                    "same": all(np.array_equal(first[v], again[v]) for v in views),
                }
        return rec


def probe(
    *,
    rig: str | Path,
    tasks: tuple[str, ...],
    checkpoints: tuple[str, ...],
    starts: int,
    models: Sequence[ModelVariant] | None = None,
    seed0: int = PROBE_SEED0,
    progress: bool = True,
) -> dict[str, Any]:
    """Probes 3-7 from ``starts`` subtasks per task × checkpoint (layouts from ``seed0``), for each model
    (default ``DEFAULT_MODELS``): ``{"models": {name: summary}, "protocol": …, "refused": […]}``."""
    from pilworld.config.rig import RigConfig
    from pilworld.paired.runner import plan_subtasks
    from pilworld.paired.stations import SimStation
    from simrig.tasks import make_task

    variants = list(models) if models is not None else resolve_models()
    rig_cfg = RigConfig.load(rig)
    plan = []
    for task in tasks:
        t = make_task(task)
        plan += plan_subtasks(task, starts, seed0, checkpoints, t.num_subtasks, t.instruction)
    records: dict[str, list[dict[str, Any]]] = {v.name: [] for v in variants}
    # Imported here: pilworld.imagine.branch and pilworld.paired import each other (as in imagine/runner.py).
    from pilworld.imagine.branch import torch_threads

    with (
        torch_threads(1),
        tempfile.TemporaryDirectory(prefix="pilworld-stability-") as folder,
        SimStation(rig, tasks[0]) as station,
    ):
        prober = _Prober(station, rig, rig_cfg, variants, checkpoints, seed0, Path(folder))
        for pair in tqdm(plan, desc="probes", unit="start", disable=not progress):
            for name, rec in prober.run(pair).items():
                records[name].append(rec)
    imaginers, errors, views = prober.imaginers, prober.errors, prober.views
    summaries = {}
    for im in imaginers:
        applies = [e.key for e in errors if im.binds_rig is not None and im.applies(e)]
        summaries[im.variant.name] = {
            "label": im.variant.label,
            "binds_rig": im.binds_rig,
            **_summarize_probes(records[im.variant.name], views, errors, applies),
        }
    protocol = {
        "tasks": list(tasks),
        "checkpoints": list(checkpoints),
        "starts_per_checkpoint": starts,
        "starts": len(plan),
        "seed0": seed0,
        "rounds": 1,
        "shuffle_rounds": SHUFFLE_ROUNDS,
        "donor_seed_offset": DONOR_SEED_OFFSET,
        "jitter_rad": JITTER_RAD,
        "jitter_seed": seed0,
        "fast_step_rad": FAST_STEP_RAD,
        "errors": [e.to_json() for e in errors],
        "models": [v.name for v in variants],
    }
    return {"models": summaries, "protocol": protocol, "refused": prober.refused}


# ---------------------------------------------------------------------- summaries


def _mean(xs: list[float]) -> float | None:
    return float(np.mean(xs)) if xs else None


def _median(xs: list[float]) -> float | None:
    return float(np.median(xs)) if xs else None


def _divergence(pairs: list[dict[str, float]]) -> dict[str, Any]:
    """Model vs simulator separation of two futures over starts: ``pairs`` of per-start {pred, real} MSEs."""
    pred = [p["pred"] for p in pairs]
    real = [p["real"] for p in pairs]
    ratios = [a / b for a, b in zip(pred, real, strict=True) if b > 1e-9]
    return {
        "mse_pred": _mean(pred),
        "mse_real": _mean(real),
        "ratio_median": _median(ratios),
        "distinct_share": float(np.mean([a > 0.0 for a in pred])) if pred else None,
    }


def _error_row(records: list[dict[str, Any]], error: RigError, views: list[str], applies: bool) -> dict[str, Any]:
    """One wrong rig: mean PSNR per view over the starts that have it, and its change from the right rig."""
    key = f"psnr:err:{error.key}"
    have = [r for r in records if key in r] if applies else []
    per_view = {v: _mean([r[key][v] for r in have]) for v in views}
    delta = {v: _mean([r[key][v] - r["psnr:policy"][v] for r in have]) for v in views}
    return {
        **error.to_json(),
        "applies": applies,
        "psnr_head": per_view.get(HEAD),
        "delta_db": delta.get(HEAD),
        "per_view": per_view,
        "delta_per_view": delta,
        "n": len(have),
    }


def _summarize_probes(
    records: list[dict[str, Any]], views: list[str], errors: Sequence[RigError], applies: Sequence[str]
) -> dict[str, Any]:
    """One model's probe figures from its per-start records; ``applies``: the keys of the errors that reach it."""
    counterfactual = []
    for alt in ("hold", "reverse"):
        row: dict[str, Any] = {"alternative": alt}
        for v in views:
            row[v] = _divergence([r[f"div:{alt}"][v] for r in records])
        counterfactual.append(row)
    baseline = {
        "psnr_head": _mean([r["psnr:policy"][HEAD] for r in records]),
        "per_view": {v: _mean([r["psnr:policy"][v] for r in records]) for v in views},
        "n": len(records),
    }
    none = {
        "kind": "none",
        "key": "none",
        "label": "the rig's calibration",
        "params": {},
        "applies": True,
        "psnr_head": baseline["psnr_head"],
        "delta_db": 0.0 if records else None,
        "per_view": baseline["per_view"],
        "delta_per_view": {v: 0.0 if records else None for v in views},
        "n": len(records),
    }
    rows = [_error_row(records, e, views, e.key in applies) for e in errors]
    ood = []
    for kind in ("policy", "fast", "jitter", "offset"):
        have = [r for r in records if f"psnr:{kind}" in r]
        ood.append(
            {
                "kind": kind,
                "psnr_head": _mean([r[f"psnr:{kind}"][HEAD] for r in have]),
                "n": len(have),
                "per_view": {v: _mean([r[f"psnr:{kind}"][v] for r in have]) for v in views},
            }
        )
    frozen = {v: _mean([r["psnr:frozen"][v] for r in records]) for v in views}
    shuffle = [r["shuffle"] for r in records if "shuffle" in r]
    per_view = {}
    for v in views:
        shuffled = [s["psnr"][v]["shuffled"] for s in shuffle]
        own = [s["psnr"][v]["own"] for s in shuffle]
        per_view[v] = {
            **_divergence([s["div"][v] for s in shuffle]),
            "psnr_shuffled": _mean(shuffled),
            "psnr_own": _mean(own),
            "gap_db": _mean([a - b for a, b in zip(own, shuffled, strict=True)]),
            "psnr_frozen": _mean([s["psnr"][v]["frozen"] for s in shuffle]),
        }
    return {
        "starts": len(records),
        "counterfactual": {"rows": counterfactual},
        "calibration": {"rows": [none] + [r for r in rows if r["kind"] in CALIBRATION_KINDS]},
        "robot_mismatch": {"baseline": baseline, "rows": [r for r in rows if r["kind"] == "robot_model"]},
        "ood_actions": {"rows": ood, "frozen_per_view": frozen},
        "action_shuffle": {
            "rounds": SHUFFLE_ROUNDS,
            "n": len(shuffle),
            "per_view": per_view,
            "deterministic_share": float(np.mean([s["same"] for s in shuffle])) if shuffle else None,
        },
    }


# ---------------------------------------------------------------------- the bench


def _probe_job(kwargs: dict[str, Any]) -> dict[str, Any]:
    """:func:`probe` in a spawned process (module level, so the pool can pickle it)."""
    return probe(**kwargs, progress=False)


def run_stability(
    *,
    rig: str | Path,
    quick: bool = False,
    out: str | Path = "bench_runs/stability",
    subtasks: int | None = None,
    starts: int | None = None,
    workers: int | None = None,
    models: Sequence[str] | None = None,
    progress: bool = True,
) -> dict[str, Any]:
    """The whole bench for ``models`` (default ``DEFAULT_MODELS``); see the module docstring."""
    from pilworld.bench.paired import failure_faithfulness
    from simrig.tasks import TASK_NAMES

    t0 = time.monotonic()
    variants = resolve_models(models)
    for v in variants:  # fail before the horizon runs, naming the missing weights
        v.check()
    rounds = max(HORIZONS)
    tasks = tuple(TASK_NAMES)
    proto = PairedProtocol(tasks, QUICK_CHECKPOINTS, subtasks or (1 if quick else 5), rounds, STABILITY_SEED0)
    horizon_protocol = {
        "tasks": list(tasks),
        "checkpoints": list(proto.checkpoints),
        "subtasks": proto.subtasks,
        "rounds": rounds,
        "seed0": proto.seed,
    }
    probe_args: dict[str, Any] = {
        "rig": str(rig),
        "tasks": tasks,
        "checkpoints": QUICK_CHECKPOINTS,
        "starts": starts or (1 if quick else 4),
        "models": variants,
        "seed0": PROBE_SEED0,
    }
    # Imported here: pilworld.imagine.branch and pilworld.paired import each other (as in imagine/runner.py).
    from pilworld.imagine.branch import torch_threads

    # The probes run in a process of their own beside the horizon runs (one core each most of the time: the
    # paired runs are sequential), unless a single process was asked for.
    with concurrent.futures.ProcessPoolExecutor(1, mp_context=mp.get_context("spawn")) as pool:
        probing = None
        if workers != 1:
            if progress:
                print("probes: in a process of their own, beside the horizon runs", flush=True)
            probing = pool.submit(_probe_job, probe_args)
        with torch_threads(1):
            results = evaluate_variants(
                variants, proto, Path(out) / "horizon", rig=rig, workers=workers, progress=progress, single_step=False
            )
        probes = probing.result() if probing is not None else probe(**probe_args, progress=progress)
    per_model: dict[str, Any] = {}
    for v in variants:
        run = Path(results[v.name]["out"])
        horizon = horizon_sweep(run, rounds, ChunkSpec().frames)
        horizon["protocol"] = horizon_protocol
        p = probes["models"][v.name]
        per_model[v.name] = {
            "label": v.label,
            "horizon": horizon,
            "failure_faithfulness": failure_faithfulness(str(run)),
            **{k: p[k] for k in p if k != "label"},
        }
    return {
        "bench": "stability",
        "quick": quick,
        "models": per_model,
        "probe_protocol": probes["protocol"],
        "refused": probes["refused"],
        "machine": machine_info(),
        "wall_s": round(time.monotonic() - t0, 1),
    }
