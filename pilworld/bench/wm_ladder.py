"""``pilworld bench wm-ladder``: the diagnostic ladder of issue #21 — where does the imagined branch lose?

The imagined branch differs from the real one in several ways at once: the policy sees generated frames,
its state is the last commanded action instead of the measured joints, the judges look at frames with
model artefacts, and the model's errors compound from round to round. Each rung isolates one of them on
the simulated rig (layouts from seed 8,000,000 on, reserved for this bench; training used 0–19), on the
same plan of pairs (tasks × scripted checkpoints × subtasks, :func:`pilworld.paired.runner.plan_subtasks`):

0. ``state_contract`` — the real branch against branches with *perfect* images (the simulator) but the
   imagined branch's state contract: every observation's state replaced by the executed stride-aligned
   commands (``commanded``), or only the arm joints commanded and the grippers measured
   (``arms_commanded``). SR by the privileged checker.
1. ``representation`` — the real branch re-run with every observation the policy sees passed through the
   world model's frame autoencoder (encode → decode; the robot itself is unaffected): SR by the checker,
   and the image-only judge (:class:`~pilworld.judges.vision.VisionJudge`) on plain and on autoencoded
   episodes — its agreement with the checker and the hallucination detector's false-positive rate (any
   flagged frame on a real episode is a false positive). ``null`` for a model without an autoencoder.
2. ``judge_fairness`` — the plain real episodes judged again after a degradation that a world model's
   frames carry without being wrong: the autoencoder, a mild Gaussian blur (σ = 1 px at 128²), and
   "artefacts" (JPEG at quality 80, per-frame noise σ = 2 levels, per-frame colour shift σ = 2 levels).
   Success agreement, false-positive rate, and the recall of one injected fault per episode
   (:mod:`pilworld.judges.faults`, found within k ± 1 as in ``pilworld bench hallucination``).
3. ``teacher_forced`` — per round r = 1..R, pooled PSNR of the model's K frames against the real K
   frames, when every round starts from the real frames (the real observation at the round start, its
   real history, the real executed chunk: one-chunk quality) and in the free closed loop (the same real
   chunks, the model's own frames fed back: compounding), beside the frozen baselines (the round's real
   start frame held, and the subtask's start frame held). Round 1 is the same in both by construction.

Everything resumes from ``--out`` (default ``bench_runs/wm_ladder``): every pair's record of every rung
is appended to ``<rung>.jsonl`` (keyed by the settings that decide it), and every real branch is kept as
``real/<key>/<pair>.npz`` and shared by the rungs (it does not depend on the world model).
"""

from __future__ import annotations

import dataclasses
import hashlib
import json
import time
from collections.abc import Callable, Iterator, Mapping, Sequence
from dataclasses import dataclass, field
from functools import partial
from pathlib import Path
from typing import Any

import numpy as np
import torch
from numpy.typing import NDArray
from tqdm import tqdm

from pilworld.bench.common import machine_info
from pilworld.config.rig import RigConfig
from pilworld.data.atomic import atomic_write, write_json
from pilworld.data.episode import Episode
from pilworld.paired.runner import PairedSubtask, plan_subtasks
from pilworld.rollout import Rollout
from pilworld.types import LEFT_GRIP, RIGHT_GRIP, ActionChunk, ChunkSpec, Observation, Segment, Start, Subtask
from pilworld.world_model.base import PredictRequest, WorldModel, WorldModelBatch, WorldModelInfo
from simrig.files import SIM_RIG

REPO_ROOT = Path(__file__).resolve().parents[2]
DEFAULT_OUT = Path("bench_runs") / "wm_ladder"
LADDER_SEED0 = 8_000_000
TASKS = ("sort_cubes", "stack_bowls", "stack_blocks")
RUNGS = ("state_contract", "representation", "judge_fairness", "teacher_forced")
STATE_MODES = ("real", "commanded", "arms_commanded")
DEGRADATIONS = ("plain", "autoencoded", "blur", "artefact")
QUICK_CHECKPOINTS = ("scripted_step_01k", "scripted_step_05k", "scripted_step_30k")
SUBTASKS = {"quick": 1, "full": 2}  # per task × checkpoint, every rung
GRIPS = (LEFT_GRIP, RIGHT_GRIP)
HEAD = "cam_high"
BLUR_SIGMA_AT_128 = 1.0  # px, scaled with the image width
JPEG_QUALITY = 80
NOISE_LEVELS = 2.0  # per-pixel Gaussian noise, uint8 levels
COLOUR_SHIFT_LEVELS = 2.0  # per-frame per-channel offset, uint8 levels
VERSION = 1  # bump when a record's meaning changes: cached records of other versions are not reused

Frames = NDArray[np.uint8]


# ---------------------------------------------------------------------- settings


@dataclass(frozen=True)
class LadderConfig:
    """What one ladder run measures; every field has the bench's default."""

    model: str = ""  # a world-model folder; "" = pilworld.world_model.DEFAULT_CHECKPOINT
    rig: str = str(SIM_RIG)
    quick: bool = False
    subtasks: int | None = None  # per task × checkpoint; None = SUBTASKS[quick | full]
    tasks: tuple[str, ...] = TASKS
    checkpoints: tuple[str, ...] | None = None  # None: QUICK_CHECKPOINTS (quick) or every scripted one
    rungs: tuple[str, ...] = RUNGS
    spec: ChunkSpec = field(default_factory=ChunkSpec)
    seed0: int = LADDER_SEED0
    out: str = str(DEFAULT_OUT)

    def __post_init__(self) -> None:
        s = self.subtasks
        if s is not None and (isinstance(s, bool) or not isinstance(s, int) or s < 1):
            raise ValueError(f"subtasks: expected an integer >= 1, got {s!r}")
        unknown = [r for r in self.rungs if r not in RUNGS]
        if unknown or not self.rungs:
            raise ValueError(f"rungs: unknown rung(s) {unknown or list(self.rungs)} (known: {', '.join(RUNGS)})")
        from simrig.tasks import TASK_NAMES

        bad = [t for t in self.tasks if t not in TASK_NAMES]
        if bad or not self.tasks:
            raise ValueError(f"tasks: unknown task(s) {bad or list(self.tasks)} (known: {', '.join(TASK_NAMES)})")
        if self.checkpoints is not None:
            from pilworld.policies.scripted import CHECKPOINTS

            names = [c.name for c in CHECKPOINTS]
            bad = [c for c in self.checkpoints if c not in names]
            if bad or not self.checkpoints:
                raise ValueError(f"checkpoints: unknown scripted checkpoint(s) {bad or []} (known: {', '.join(names)})")

    @property
    def model_path(self) -> Path:
        from pilworld.world_model import V1_CHECKPOINT

        return Path(self.model) if self.model else Path(V1_CHECKPOINT)  # the ladder was first climbed with v1

    @property
    def subtasks_per_setting(self) -> int:
        return self.subtasks if self.subtasks is not None else SUBTASKS["quick" if self.quick else "full"]

    @property
    def checkpoint_names(self) -> tuple[str, ...]:
        if self.checkpoints is not None:
            return self.checkpoints
        if self.quick:
            return QUICK_CHECKPOINTS
        from pilworld.policies.scripted import CHECKPOINTS

        return tuple(c.name for c in CHECKPOINTS)

    def plan(self) -> list[PairedSubtask]:
        from simrig.tasks import make_task

        plan: list[PairedSubtask] = []
        for t in self.tasks:
            task = make_task(t)
            plan += plan_subtasks(
                t, self.subtasks_per_setting, self.seed0, self.checkpoint_names, task.num_subtasks, task.instruction
            )
        return plan


def check_model_folder(path: Path) -> None:
    """A one-line ``ValueError`` unless ``path`` is a world-model folder load_world_model can read."""
    from pilworld.world_model.folder import CONFIG_FILE

    if not path.is_dir():
        raise ValueError(f"model: {path} is not a folder (expected a world-model folder with {CONFIG_FILE})")
    if not (path / CONFIG_FILE).is_file():
        raise ValueError(f"model: {path} is not a world-model folder ({CONFIG_FILE} missing)")


def _digest(obj: Any) -> str:
    return hashlib.sha256(json.dumps(obj, sort_keys=True, default=str).encode()).hexdigest()[:16]


def _safe(pair_id: str) -> str:
    return pair_id.replace("/", "__")


# ---------------------------------------------------------------------- the world model and its autoencoder


class SeedShifted:
    """``model`` with every seed shifted by ``offset``: a teacher-forced round r draws the noise of round r."""

    def __init__(self, model: WorldModel, offset: int) -> None:
        self.model = model
        self.offset = offset

    @property
    def info(self) -> WorldModelInfo:
        return self.model.info

    def predict_batch(self, batch: WorldModelBatch, *, steps: int | None = None, seed: int = 0) -> torch.Tensor:
        return self.model.predict_batch(batch, steps=steps, seed=seed + self.offset)

    def predict(self, request: PredictRequest, *, steps: int | None = None, seed: int = 0) -> dict[str, Frames]:
        return self.model.predict(request, steps=steps, seed=seed + self.offset)

    def __getattr__(self, name: str) -> Any:
        """A model that also predicts the reported state (``predict_with_state``) keeps it, seed shifted."""
        if name == "predict_with_state":
            inner = getattr(self.__dict__["model"], name)  # AttributeError when the model has none

            def shifted(request: PredictRequest, *, steps: int | None = None, seed: int = 0) -> Any:
                return inner(request, steps=steps, seed=seed + self.offset)

            return shifted
        raise AttributeError(name)


class FrameAutoencoder:
    """Frames through a native model's frame VAE: ``E`` (latent means) then plain ``D`` (no gated residual).

    A model seen through :class:`~pilworld.world_model.resized.ResizedWorldModel` is autoencoded at its
    own size (frames area-resized down, decoded frames bilinear-resized back), as it would see them.
    """

    def __init__(
        self,
        encode: Callable[[torch.Tensor], torch.Tensor],
        decode: Callable[[torch.Tensor], torch.Tensor],
        native: tuple[int, int] | None = None,
        batch: int = 48,
    ) -> None:
        self._encode = encode
        self._decode = decode
        self.native = native  # (width, height) to autoencode at, None = the frames' own size
        self.batch = batch

    def __call__(self, frames: Frames) -> Frames:
        """uint8 [N, H, W, 3] → the autoencoded uint8 [N, H, W, 3]."""
        from pilworld.world_model.batching import resize_images
        from pilworld.world_model.resized import upsample_images
        from pilworld.world_model.vae import to_uint8

        arr = np.asarray(frames, dtype=np.uint8)
        h, w = arr.shape[-3], arr.shape[-2]
        out = []
        for i in range(0, arr.shape[0], self.batch):
            x = torch.from_numpy(np.ascontiguousarray(np.moveaxis(arr[i : i + self.batch], -1, -3)))
            if self.native is not None:
                x = resize_images(x, self.native[1], self.native[0])
            with torch.no_grad():
                y = to_uint8(self._decode(self._encode(x)).clamp(-1.0, 1.0))
            if self.native is not None:
                y = upsample_images(y, h, w)
            out.append(np.moveaxis(y.numpy(), -3, -1))
        return np.ascontiguousarray(np.concatenate(out))

    def images(self, images: Mapping[str, Frames]) -> dict[str, Frames]:
        """One observation's views (each [H, W, 3]) autoencoded in one call."""
        views = list(images)
        done = self(np.stack([np.asarray(images[v]) for v in views]))
        return {v: done[i] for i, v in enumerate(views)}


def autoencoder_for(model: WorldModel) -> FrameAutoencoder | str:
    """The model's frame autoencoder, or why it has none (a string)."""
    from pilworld.world_model.resized import ResizedWorldModel

    inner: Any = model
    native: tuple[int, int] | None = None
    if isinstance(model, ResizedWorldModel):
        inner = model.model
        native = model.native_size
    encode, decode = getattr(inner, "encode", None), getattr(inner, "decode_unit", None)
    if not callable(encode) or not callable(decode):
        return f"{type(inner).__name__} has no frame autoencoder (no encode / decode_unit)"
    return FrameAutoencoder(encode, decode, native)


def load_ladder_model(path: Path, rig: RigConfig, spec: ChunkSpec, task: str) -> tuple[WorldModel, str | None, bool]:
    """(model, adapter, resized): the folder's model with ``task``'s adapter when it has one, at the rig's size."""
    from pilworld.world_model.loader import adapter_names, load_world_model
    from pilworld.world_model.resized import ResizedWorldModel

    check_model_folder(path)
    adapter = task if task in adapter_names(path) else None
    model: WorldModel = load_world_model(path, adapter=adapter)
    bind_rig = getattr(model, "bind_rig", None)
    if callable(bind_rig):  # a model that composites the rig's geometry uses this rig's calibration
        bind_rig(rig)
    info = model.info
    if set(info.views) != set(rig.cameras):
        raise ValueError(f"model: {path} predicts views {list(info.views)}, the rig has {list(rig.cameras)}")
    if info.future != spec.frames:
        raise ValueError(f"model: {path} predicts K={info.future} frames per round, the ladder uses K={spec.frames}")
    size = (rig.image_size.width, rig.image_size.height)
    resized = (info.width, info.height) != size
    if resized:
        model = ResizedWorldModel(model, height=size[1], width=size[0])
    return model, adapter, resized


# ---------------------------------------------------------------------- environment wrappers


class _Wrapped:
    """Delegates the :class:`~pilworld.envs.base.Env` contract to ``env``."""

    def __init__(self, env: Any) -> None:
        self.env = env

    @property
    def origin(self) -> str:
        return str(self.env.origin)

    @property
    def spec(self) -> ChunkSpec:
        spec: ChunkSpec = self.env.spec
        return spec


class StateContractEnv(_Wrapped):
    """A real branch whose observations report the imagined branch's state contract.

    ``commanded``: every observation's state is the executed stride-aligned command
    (``segment.actions[spec.stride_indices()]``), as :class:`~pilworld.envs.ImaginedEnv` reports it;
    ``arms_commanded``: the arm joints commanded, the grippers measured; ``real``: unchanged. The start
    observation is the real start in every mode (the imagined branch starts from it too). Images are the
    simulator's own. ``gaps`` collects |reported − measured| per observation (arms, grippers).
    """

    def __init__(self, env: Any, mode: str) -> None:
        if mode not in STATE_MODES:
            raise ValueError(f"mode: expected one of {list(STATE_MODES)}, got {mode!r}")
        super().__init__(env)
        self.mode = mode
        self.gaps: list[tuple[float, float]] = []

    def reset(self, start: Start) -> Observation:
        self.gaps = []
        obs: Observation = self.env.reset(start)
        return obs

    def step(self, chunk: ActionChunk | NDArray[np.floating]) -> Segment:
        seg: Segment = self.env.step(chunk)
        if self.mode == "real":
            return seg
        commanded = np.asarray(seg.actions, dtype=np.float32)[self.spec.stride_indices()]
        grips = list(GRIPS)
        observations = []
        for k, o in enumerate(seg.observations):
            measured = np.asarray(o.state, dtype=np.float32)
            state = commanded[k].copy()
            if self.mode == "arms_commanded":
                state[grips] = measured[grips]
            diff = np.abs(state - measured)
            arms = np.ones(diff.shape[0], dtype=bool)
            arms[grips] = False
            self.gaps.append((float(diff[arms].mean()), float(diff[grips].mean())))
            observations.append(Observation(images=o.images, state=state, timestamp=o.timestamp))
        return Segment(observations=tuple(observations), actions=seg.actions, stride=seg.stride)


class AutoencodedEnv(_Wrapped):
    """A branch whose every observation (the start included) reaches the policy through ``autoencode``.

    Only the images change; states, timestamps and what the robot executes are untouched. ``start_observation``
    is the autoencoded start the policy saw; ``mse`` collects per-view squared errors (levels²) of the
    autoencoded frames against the originals.
    """

    def __init__(self, env: Any, autoencode: FrameAutoencoder) -> None:
        super().__init__(env)
        self.autoencode = autoencode
        self.start_observation: Observation | None = None
        self.mse: dict[str, list[float]] = {}

    def _convert(self, o: Observation) -> Observation:
        images = self.autoencode.images(o.images)
        for v, img in images.items():
            err = np.asarray(img, dtype=np.float64) - np.asarray(o.images[v], dtype=np.float64)
            self.mse.setdefault(v, []).append(float(np.mean(err**2)))
        return Observation(images=images, state=o.state, timestamp=o.timestamp)

    def reset(self, start: Start) -> Observation:
        self.mse = {}
        self.start_observation = self._convert(self.env.reset(start))
        return self.start_observation

    def step(self, chunk: ActionChunk | NDArray[np.floating]) -> Segment:
        seg: Segment = self.env.step(chunk)
        views = list(seg.observations[0].images)
        flat = np.stack([np.asarray(o.images[v]) for o in seg.observations for v in views])
        done = self.autoencode(flat).reshape(len(seg.observations), len(views), *flat.shape[1:])
        observations = []
        for k, o in enumerate(seg.observations):
            for i, v in enumerate(views):
                err = done[k, i].astype(np.float64) - np.asarray(o.images[v], dtype=np.float64)
                self.mse.setdefault(v, []).append(float(np.mean(err**2)))
            images = {v: done[k, i] for i, v in enumerate(views)}
            observations.append(Observation(images=images, state=o.state, timestamp=o.timestamp))
        return Segment(observations=tuple(observations), actions=seg.actions, stride=seg.stride)


# ---------------------------------------------------------------------- degradations (judge fairness)


def blur_frames(frames: Frames, sigma_px: float) -> Frames:
    """Gaussian blur of σ px on every frame [N, H, W, 3]."""
    import cv2

    return np.stack([cv2.GaussianBlur(f, (0, 0), sigmaX=sigma_px, borderType=cv2.BORDER_REFLECT) for f in frames])


def artefact_frames(frames: Frames, rng: np.random.Generator) -> Frames:
    """JPEG at :data:`JPEG_QUALITY`, then per-pixel noise and a per-frame per-channel colour shift."""
    import cv2

    out = []
    for f in frames:
        ok, buf = cv2.imencode(".jpg", cv2.cvtColor(f, cv2.COLOR_RGB2BGR), [cv2.IMWRITE_JPEG_QUALITY, JPEG_QUALITY])
        if not ok:
            raise RuntimeError("JPEG encoding failed")
        decoded = cv2.imdecode(buf, cv2.IMREAD_COLOR)
        if decoded is None:
            raise RuntimeError("JPEG decoding failed")
        g = cv2.cvtColor(decoded, cv2.COLOR_BGR2RGB).astype(np.float64)
        g += rng.normal(0.0, NOISE_LEVELS, g.shape) + rng.normal(0.0, COLOUR_SHIFT_LEVELS, 3)
        out.append(np.clip(np.round(g), 0, 255).astype(np.uint8))
    return np.stack(out)


def degrade_episode(
    ep: Episode, kind: str, *, autoencode: FrameAutoencoder | None = None, rng: np.random.Generator | None = None
) -> Episode:
    """``ep`` with every view's frames degraded (``plain``: unchanged); states and actions untouched."""
    if kind == "plain":
        return ep
    images: dict[str, Frames] = {}
    for v, frames in ep.images.items():
        f = np.asarray(frames, dtype=np.uint8)
        if kind == "autoencoded":
            if autoencode is None:
                raise ValueError("degrade_episode: 'autoencoded' needs an autoencoder")
            images[v] = autoencode(f)
        elif kind == "blur":
            images[v] = blur_frames(f, BLUR_SIGMA_AT_128 * f.shape[2] / 128.0)
        elif kind == "artefact":
            images[v] = artefact_frames(f, rng if rng is not None else np.random.default_rng(0))
        else:
            raise ValueError(f"degradation: expected one of {list(DEGRADATIONS)}, got {kind!r}")
    return dataclasses.replace(ep, images=images)


# ---------------------------------------------------------------------- real branches, kept on disk


def save_rollout(path: Path, rollout: Rollout, meta: dict[str, Any]) -> None:
    """A real-branch rollout (start, history, segments, chunks) and ``meta`` as one compressed npz."""
    obs = rollout.observations
    views = list(rollout.start.observation.views)
    hist = list(rollout.start.history)
    arrays: dict[str, Any] = {}
    for i, v in enumerate(views):
        arrays[f"img{i}"] = np.stack([np.asarray(o.images[v]) for o in obs])
        if hist:
            arrays[f"hist{i}"] = np.stack([np.asarray(o.images[v]) for o in hist])
    arrays["state"] = np.stack([o.state for o in obs]).astype(np.float32)
    arrays["time"] = np.array([o.timestamp for o in obs], dtype=np.float64)
    arrays["hist_state"] = np.array([o.state for o in hist], dtype=np.float32).reshape(len(hist), -1)
    arrays["hist_time"] = np.array([o.timestamp for o in hist], dtype=np.float64)
    arrays["actions"] = np.stack([s.actions for s in rollout.segments]).astype(np.float32)
    arrays["chunks"] = np.stack(rollout.chunks).astype(np.float32)
    sub = rollout.start.subtask
    info = {
        **meta,
        "views": views,
        "stride": rollout.segments[0].stride,
        "seg_len": [len(s.observations) for s in rollout.segments],
        "subtask": dataclasses.asdict(sub),
        "instruction": rollout.instruction,
        "origin": rollout.origin,
    }
    arrays["meta"] = np.array(json.dumps(info))

    def write(tmp: Path) -> None:
        with tmp.open("wb") as fh:
            np.savez_compressed(fh, **arrays)

    atomic_write(path, write, durable=False)


def load_rollout(path: Path) -> tuple[Rollout, dict[str, Any]]:
    """The rollout and meta :func:`save_rollout` wrote."""
    with np.load(path) as z:
        info = json.loads(str(z["meta"]))
        views = info["views"]
        imgs = [z[f"img{i}"] for i in range(len(views))]
        hists = [z[f"hist{i}"] for i in range(len(views))] if f"hist{0}" in z.files else None
        state, times = z["state"], z["time"]
        hist_state, hist_time = z["hist_state"], z["hist_time"]
        actions, chunks = z["actions"], z["chunks"]

    def obs_at(i: int) -> Observation:
        return Observation(
            images={v: imgs[j][i] for j, v in enumerate(views)}, state=state[i], timestamp=float(times[i])
        )

    history: tuple[Observation, ...] = ()
    if hists is not None:
        history = tuple(
            Observation(
                images={v: hists[j][i] for j, v in enumerate(views)}, state=hist_state[i], timestamp=float(hist_time[i])
            )
            for i in range(len(hist_time))
        )
    start = Start(subtask=Subtask(**info["subtask"]), observation=obs_at(0), history=history)
    segments, at = [], 1
    for r, n in enumerate(info["seg_len"]):
        segments.append(Segment(tuple(obs_at(at + k) for k in range(n)), actions=actions[r], stride=info["stride"]))
        at += n
    rollout = Rollout(
        origin=info["origin"], start=start, instruction=info["instruction"], segments=segments, chunks=list(chunks)
    )
    return rollout, info


# ---------------------------------------------------------------------- the lab: robot, policies, models, caches


class RecordCache:
    """Per-pair records of one rung in ``<out>/<rung>.jsonl``, reused when their settings key matches."""

    def __init__(self, path: Path, key: str) -> None:
        self.path = path
        self.key = key
        self.records: dict[str, dict[str, Any]] = {}
        if path.is_file():
            for line in path.read_text().splitlines():
                try:
                    row = json.loads(line)
                except json.JSONDecodeError:
                    continue  # a line cut by a kill
                if row.get("key") == key:
                    self.records[row["pair"]] = row["record"]

    def get(self, pair: str) -> dict[str, Any] | None:
        return self.records.get(pair)

    def put(self, pair: str, record: dict[str, Any]) -> None:
        self.records[pair] = record
        self.path.parent.mkdir(parents=True, exist_ok=True)
        with self.path.open("a") as fh:
            fh.write(json.dumps({"key": self.key, "pair": pair, "record": record}) + "\n")


class Lab:
    """The simulated robot, the policies, the world models per task and the real-branch store of one run."""

    def __init__(self, cfg: LadderConfig) -> None:
        from pilworld.control_video.gamma import ControlVideo

        self.cfg = cfg
        self.spec = cfg.spec
        self.rig_cfg = RigConfig.load(cfg.rig)
        self.out = Path(cfg.out)
        self.model_path = cfg.model_path
        check_model_folder(self.model_path)
        self.gamma = ControlVideo.from_rig(self.rig_cfg, self.spec)
        spec_json = dataclasses.asdict(self.spec)
        self.real_key = _digest({"v": VERSION, "rig": str(Path(cfg.rig).resolve()), "spec": spec_json})
        self.model_key = _digest({"real": self.real_key, "model": str(self.model_path.resolve())})
        self._robot: Any = None
        self._policies: dict[str, Any] = {}
        self._models: dict[str, tuple[WorldModel, str | None, bool]] = {}
        self.real_runs = 0

    # -- resources, made on first use

    @property
    def robot(self) -> Any:
        if self._robot is None:
            from simrig.robot import SimRobot

            self._robot = SimRobot(self.rig_cfg, self.cfg.tasks[0])
            self._robot.connect()
        return self._robot

    def close(self) -> None:
        if self._robot is not None:
            self._robot.disconnect()
            self._robot = None

    def policy(self, checkpoint: str) -> Any:
        if checkpoint not in self._policies:
            from pilworld.policies.registry import make_policy

            self._policies[checkpoint] = make_policy(checkpoint, self.rig_cfg, self.spec)
        return self._policies[checkpoint]

    def model(self, task: str) -> tuple[WorldModel, str | None, bool]:
        if task not in self._models:
            self._models[task] = load_ladder_model(self.model_path, self.rig_cfg, self.spec, task)
        return self._models[task]

    def start(self, pair: PairedSubtask) -> Start:
        sub = pair.subtask
        start: Start = self.robot.reset(
            seed=sub.seed, subtask=sub.index, task=sub.task, history=self.spec.history, stride=self.spec.stride
        )
        return start

    def run_branch(self, pair: PairedSubtask, wrap: Callable[[Any], Any] | None = None) -> tuple[Rollout, Any, bool]:
        """One real-branch run of ``pair`` (the env optionally wrapped): (rollout, env, checker success)."""
        from pilworld.envs import RobotEnv
        from pilworld.rollout import closed_loop

        start = self.start(pair)
        policy = self.policy(pair.checkpoint)
        policy.reset(seed=pair.seed)
        env: Any = RobotEnv(self.robot, self.spec, pace=False)
        if wrap is not None:
            env = wrap(env)
        rollout = closed_loop(policy, env, pair.subtask.instruction, self.spec.rounds, start=start)
        success = bool(self.robot.check_subtask(pair.subtask.index).success)
        return rollout, env, success

    def real(self, pair: PairedSubtask) -> tuple[Rollout, bool]:
        """The plain real branch of ``pair`` and its checker verdict, run once and kept on disk."""
        path = self.out / "real" / self.real_key / f"{_safe(pair.pair_id)}.npz"
        if path.is_file():
            try:
                rollout, info = load_rollout(path)
                return rollout, bool(info["success"])
            except (OSError, ValueError, KeyError):
                path.unlink(missing_ok=True)  # a damaged file: run it again
        rollout, _, success = self.run_branch(pair)
        save_rollout(path, rollout, {"success": success, "pair": pair.pair_id})
        self.real_runs += 1
        return rollout, success

    def episode(self, pair: PairedSubtask, rollout: Rollout) -> Episode:
        from pilworld.collection.tasks import task_extra
        from pilworld.paired.episodes import rollout_episode
        from simrig.tasks import load_task

        return rollout_episode(
            rollout,
            checkpoint=pair.checkpoint,
            seed=pair.seed,
            extra={"pair": pair.pair_id, **task_extra(load_task(pair.subtask.task))},
        )

    def context(self, task: str) -> Any:
        from pilworld.judges.base import JudgeContext

        return JudgeContext(rig=self.rig_cfg, task=task)


# ---------------------------------------------------------------------- statistics


def _rate(values: Sequence[float | bool | None]) -> dict[str, Any]:
    """Mean of the non-missing values, their count and a 95 % bootstrap interval."""
    from pilworld.metrics.bootstrap import bootstrap_means

    col = np.array([np.nan if v is None else float(v) for v in values], dtype=np.float64)
    ok = np.isfinite(col)
    if not ok.any():
        return {"rate": None, "n": 0, "ci95": None}
    return {"rate": round(float(col[ok].mean()), 4), "n": int(ok.sum()), "ci95": _r(bootstrap_means({"x": col})["x"])}


def _r(x: Any, digits: int = 4) -> Any:
    if isinstance(x, float):
        return round(x, digits)
    if isinstance(x, list):
        return [_r(v, digits) for v in x]
    return x


def _paired_rates(columns: Mapping[str, Sequence[bool]], reference: str) -> dict[str, Any]:
    """SR per column with 95 % intervals, and each column's paired difference to ``reference``."""
    from pilworld.metrics.bootstrap import bootstrap_means

    cols = {k: np.array([float(v) for v in vals], dtype=np.float64) for k, vals in columns.items()}
    others = [k for k in cols if k != reference]
    ci = bootstrap_means(cols, differences={f"d_{k}": (k, reference) for k in others})
    return {
        "sr": {k: round(float(v.mean()), 4) for k, v in cols.items()},
        "sr_ci95": {k: _r(ci[k]) for k in cols},
        "delta_vs_" + reference: {k: round(float(cols[k].mean() - cols[reference].mean()), 4) for k in others},
        "delta_ci95": {k: _r(ci[f"d_{k}"]) for k in others},
        "flips": {
            k: {
                "lost": int(np.sum((cols[reference] == 1) & (cols[k] == 0))),
                "gained": int(np.sum((cols[reference] == 0) & (cols[k] == 1))),
            }
            for k in others
        },
    }


def _per_task(records: Sequence[tuple[PairedSubtask, dict[str, Any]]], keys: Sequence[str]) -> dict[str, Any]:
    out: dict[str, Any] = {}
    for task in dict.fromkeys(p.subtask.task for p, _ in records):
        rows = [r for p, r in records if p.subtask.task == task]
        out[task] = {"n": len(rows), **{k: round(float(np.mean([r[k] for r in rows])), 4) for k in keys}}
    return out


def _psnr(mse_value: float) -> float:
    from pilworld.world_model.metrics import psnr_from_mse

    return round(float(psnr_from_mse(torch.tensor(float(mse_value), dtype=torch.float64))), 3)


def _frame_mse(a: Frames, b: Frames) -> float:
    """Mean squared error (levels²) over all frames and pixels of two [N, H, W, 3] stacks."""
    return float(np.mean((np.asarray(a, dtype=np.float64) - np.asarray(b, dtype=np.float64)) ** 2))


def _judgement(verdict: Any) -> dict[str, Any]:
    return {
        "success": bool(verdict.success),
        "hallucination_frame": verdict.first_hallucination_frame,
        "reason": verdict.reason,
    }


def _judge_summary(rows: Sequence[tuple[bool, dict[str, Any]]]) -> dict[str, Any]:
    """Agreement of the image-only judge with the checker, its confusion matrix and the false-positive rate."""
    confusion = {"tp": 0, "fp": 0, "fn": 0, "tn": 0}
    categories: dict[str, int] = {}
    for truth, j in rows:
        said = bool(j["success"])
        confusion[("tp" if truth else "fp") if said else ("fn" if truth else "tn")] += 1
        if j["hallucination_frame"] is not None:
            cat = str(j["reason"]).split("hallucination: ", 1)[-1].split(":", 1)[0]
            categories[cat] = categories.get(cat, 0) + 1
    agree = _rate([bool(j["success"]) == truth for truth, j in rows])
    fp = _rate([j["hallucination_frame"] is not None for _, j in rows])
    return {
        "n": len(rows),
        "agreement": agree["rate"],
        "agreement_ci95": agree["ci95"],
        "sr_judge": round(float(np.mean([bool(j["success"]) for _, j in rows])), 4) if rows else None,
        "confusion": confusion,
        "hallucination_fp_rate": fp["rate"],
        "hallucination_fp_ci95": fp["ci95"],
        "fp_categories": categories,
    }


def _pairs_of(cache: RecordCache, plan: Sequence[PairedSubtask]) -> list[tuple[PairedSubtask, dict[str, Any]]]:
    out = []
    for p in plan:
        rec = cache.get(p.pair_id)
        if rec is not None:
            out.append((p, rec))
    return out


def _each(
    lab: Lab,
    rung: str,
    key: dict[str, Any],
    plan: Sequence[PairedSubtask],
    record: Callable[[PairedSubtask, int], dict[str, Any]],
    progress: bool,
) -> list[tuple[PairedSubtask, dict[str, Any]]]:
    """Every pair's record of ``rung`` (cached ones reused), with a progress bar."""
    cache = RecordCache(lab.out / f"{rung}.jsonl", _digest({"v": VERSION, "rung": rung, **key}))
    todo = [(i, p) for i, p in enumerate(plan) if cache.get(p.pair_id) is None]
    bar = tqdm(
        total=len(plan), initial=len(plan) - len(todo), desc=f"wm-ladder {rung}", unit="pair", disable=not progress
    )
    for i, p in todo:
        cache.put(p.pair_id, record(p, i))
        bar.update(1)
    bar.close()
    return _pairs_of(cache, plan)


# ---------------------------------------------------------------------- rung 0: the state contract


def state_contract_record(lab: Lab, pair: PairedSubtask, index: int) -> dict[str, Any]:
    _, real_ok = lab.real(pair)
    rec: dict[str, Any] = {"real": real_ok}
    for mode in STATE_MODES[1:]:
        _, env, ok = lab.run_branch(pair, partial(StateContractEnv, mode=mode))
        rec[mode] = ok
        gaps = np.array(env.gaps, dtype=np.float64).reshape(-1, 2)
        rec[f"{mode}_gap"] = [round(float(gaps[:, 0].mean()), 5), round(float(gaps[:, 1].mean()), 5)]
    return rec


def state_contract_summary(records: Sequence[tuple[PairedSubtask, dict[str, Any]]]) -> dict[str, Any]:
    cols = {m: [bool(r[m]) for _, r in records] for m in STATE_MODES}
    gaps = {m: np.array([r[f"{m}_gap"] for _, r in records], dtype=np.float64) for m in STATE_MODES[1:]}
    return {
        "n": len(records),
        "modes": list(STATE_MODES),
        **_paired_rates(cols, "real"),
        "per_task": _per_task(records, STATE_MODES),
        "state_gap": {
            m: {"arms_rad": round(float(g[:, 0].mean()), 5), "grippers": round(float(g[:, 1].mean()), 5)}
            for m, g in gaps.items()
        },
    }


# ---------------------------------------------------------------------- rung 1: representation


def representation_record(lab: Lab, pair: PairedSubtask, index: int) -> dict[str, Any]:
    from pilworld.judges.vision import VisionJudge

    model, _, _ = lab.model(pair.subtask.task)
    ae = autoencoder_for(model)
    assert isinstance(ae, FrameAutoencoder)
    judge, ctx = VisionJudge(), lab.context(pair.subtask.task)
    rollout, real_ok = lab.real(pair)
    plain = _judgement(judge.judge(lab.episode(pair, rollout), ctx))
    ae_rollout, env, ae_ok = lab.run_branch(pair, lambda e: AutoencodedEnv(e, ae))
    # The policy saw the autoencoded start: store that as frame 0 of the autoencoded episode.
    ae_rollout = dataclasses.replace(
        ae_rollout, start=dataclasses.replace(ae_rollout.start, observation=env.start_observation)
    )
    autoencoded = _judgement(judge.judge(lab.episode(pair, ae_rollout), ctx))
    return {
        "real": real_ok,
        "autoencoded": ae_ok,
        "judge_plain": plain,
        "judge_autoencoded": autoencoded,
        "ae_mse": {v: float(np.mean(m)) for v, m in env.mse.items()},
    }


def representation_summary(records: Sequence[tuple[PairedSubtask, dict[str, Any]]]) -> dict[str, Any]:
    cols = {k: [bool(r[k]) for _, r in records] for k in ("real", "autoencoded")}
    views = list(records[0][1]["ae_mse"]) if records else []
    return {
        "n": len(records),
        **_paired_rates(cols, "real"),
        "per_task": _per_task(records, ("real", "autoencoded")),
        "judges": {
            "plain": _judge_summary([(bool(r["real"]), r["judge_plain"]) for _, r in records]),
            "autoencoded": _judge_summary([(bool(r["autoencoded"]), r["judge_autoencoded"]) for _, r in records]),
        },
        "autoencoder_psnr": {
            **{v: _psnr(float(np.mean([r["ae_mse"][v] for _, r in records]))) for v in views},
            "all": _psnr(float(np.mean([np.mean(list(r["ae_mse"].values())) for _, r in records]))) if views else None,
        },
    }


# ---------------------------------------------------------------------- rung 2: judge fairness


def judge_fairness_record(
    lab: Lab, pair: PairedSubtask, index: int, *, degradations: Sequence[str] = DEGRADATIONS
) -> dict[str, Any]:
    from pilworld.bench.hallucination import inject_random
    from pilworld.judges.faults import FAULTS
    from pilworld.judges.hallucination import HallucinationDetector
    from pilworld.judges.vision import VisionJudge

    rollout, real_ok = lab.real(pair)
    ep = lab.episode(pair, rollout)
    ctx = lab.context(pair.subtask.task)
    judge, detector = VisionJudge(), HallucinationDetector()
    ae = autoencoder_for(lab.model(pair.subtask.task)[0]) if "autoencoded" in degradations else None
    fault = FAULTS[index % len(FAULTS)]  # every degradation of a pair gets the same fault at the same frame
    rec: dict[str, Any] = {"real": real_ok, "fault": fault}
    for d in degradations:
        noise = np.random.default_rng([lab.cfg.seed0, index, 17])
        degraded = degrade_episode(ep, d, autoencode=ae if isinstance(ae, FrameAutoencoder) else None, rng=noise)
        row: dict[str, Any] = _judgement(judge.judge(degraded, ctx))
        row["mse"] = {v: _frame_mse(degraded.images[v], ep.images[v]) for v in ep.images}
        case = inject_random(fault, degraded, lab.rig_cfg, np.random.default_rng([lab.cfg.seed0, index, 21]))
        if case is None:
            row["fault_outcome"] = "skipped"
        else:
            faulted, k = case
            f = detector.judge(faulted, ctx).first_hallucination_frame
            row["fault_k"] = k
            row["fault_frame"] = f
            row["fault_outcome"] = (
                "missed" if f is None else "detected" if abs(f - k) <= 1 else "early" if f < k else "late"
            )
        rec[d] = row
    return rec


def judge_fairness_summary(
    records: Sequence[tuple[PairedSubtask, dict[str, Any]]], degradations: Sequence[str]
) -> dict[str, Any]:
    out: dict[str, Any] = {"n": len(records), "degradations": list(degradations)}
    for d in degradations:
        rows = [(bool(r["real"]), r[d]) for _, r in records]
        outcomes = [j["fault_outcome"] for _, j in rows]
        counts = {o: outcomes.count(o) for o in ("detected", "early", "late", "missed", "skipped")}
        recall = _rate([o == "detected" for o in outcomes if o != "skipped"])
        views = list(rows[0][1]["mse"]) if rows else []
        out[d] = {
            **_judge_summary(rows),
            "fault_recall": recall["rate"],
            "fault_recall_ci95": recall["ci95"],
            "fault_n": recall["n"],
            "fault_outcomes": counts,
            "psnr_vs_plain": {v: _psnr(float(np.mean([j["mse"][v] for _, j in rows]))) for v in views},
        }
    out["sr_checker"] = _rate([bool(r["real"]) for _, r in records])
    out["fault_types"] = {
        f: sum(1 for _, r in records if r["fault"] == f) for f in dict.fromkeys(r["fault"] for _, r in records)
    }
    return out


# ---------------------------------------------------------------------- rung 3: teacher-forced vs free


def _real_sequence(rollout: Rollout) -> list[Observation]:
    """The real history frames, then the start, then every recorded frame."""
    return [*rollout.start.history, *rollout.observations]


def _imagined_env(lab_gamma: Any, model: WorldModel, spec: ChunkSpec, rate_hz: float, seed: int) -> Any:
    from pilworld.envs import ImaginedEnv

    # No safety filter: the chunks replayed are the real branch's executed commands, already filtered.
    return ImaginedEnv(model, lab_gamma, spec, control_rate_hz=rate_hz, seed=seed, safety=None)


def teacher_forced_predictions(
    model: WorldModel, gamma: Any, spec: ChunkSpec, rollout: Rollout, seed: int, rate_hz: float
) -> Iterator[tuple[int, dict[str, Frames], dict[str, Frames]]]:
    """Per round r: (r, teacher-forced prediction, free prediction), each {view: uint8[K, H, W, 3]}.

    Teacher-forced round r: a fresh imagined branch reset at the real observation that starts round r with
    the real frames before it as history, stepping the real executed chunk of round r, with round r's noise
    seed. Free: one imagined branch from the real start stepping the real executed chunks in turn (its own
    frames fed back). Round 0 is the same call in both.
    """
    seq = _real_sequence(rollout)
    hist = len(rollout.start.history)
    free = _imagined_env(gamma, model, spec, rate_hz, seed)
    free.reset(rollout.start)
    at = hist
    for r, segment in enumerate(rollout.segments):
        executed = np.asarray(segment.actions, dtype=np.float32)
        start_r = Start(
            subtask=rollout.start.subtask, observation=seq[at], history=tuple(seq[max(0, at - spec.history) : at])
        )
        tf = _imagined_env(gamma, SeedShifted(model, r), spec, rate_hz, seed)
        tf.reset(start_r)
        tf_seg: Segment = tf.step(executed)
        free_seg: Segment = free.step(executed)
        views = list(seq[0].images)
        yield (
            r,
            {v: np.stack([np.asarray(o.images[v]) for o in tf_seg.observations]) for v in views},
            {v: np.stack([np.asarray(o.images[v]) for o in free_seg.observations]) for v in views},
        )
        at += len(segment.observations)


def teacher_forced_record(lab: Lab, pair: PairedSubtask, index: int) -> dict[str, Any]:
    rollout, _ = lab.real(pair)
    model, _, _ = lab.model(pair.subtask.task)
    return teacher_forced_errors(model, lab.gamma, lab.spec, rollout, pair.seed, lab.rig_cfg.control_rate_hz)


def teacher_forced_errors(
    model: WorldModel, gamma: Any, spec: ChunkSpec, rollout: Rollout, seed: int, rate_hz: float
) -> dict[str, Any]:
    """Per round and view, the MSE (levels², over the round's K frames) of teacher-forced, free and frozen."""
    seq = rollout.observations
    views = list(seq[0].views)
    out: dict[str, list[dict[str, float]]] = {"teacher_forced": [], "free": [], "frozen": [], "frozen_start": []}
    at = 0
    for r, tf, free in teacher_forced_predictions(model, gamma, spec, rollout, seed, rate_hz):
        n = len(rollout.segments[r].observations)
        real = {v: np.stack([np.asarray(o.images[v]) for o in seq[at + 1 : at + 1 + n]]) for v in views}
        held = {v: np.repeat(np.asarray(seq[at].images[v])[None], n, axis=0) for v in views}
        first = {v: np.repeat(np.asarray(seq[0].images[v])[None], n, axis=0) for v in views}
        out["teacher_forced"].append({v: _frame_mse(tf[v], real[v]) for v in views})
        out["free"].append({v: _frame_mse(free[v], real[v]) for v in views})
        out["frozen"].append({v: _frame_mse(held[v], real[v]) for v in views})
        out["frozen_start"].append({v: _frame_mse(first[v], real[v]) for v in views})
        at += n
    return out


def teacher_forced_summary(
    records: Sequence[tuple[PairedSubtask, dict[str, Any]]], views: Sequence[str]
) -> dict[str, Any]:
    kinds = ("teacher_forced", "free", "frozen", "frozen_start")
    rounds = max((len(r["free"]) for _, r in records), default=0)
    rows = []
    per_view: dict[str, dict[str, list[float | None]]] = {v: {k: [] for k in kinds} for v in [*views, "all"]}
    for i in range(rounds):
        have = [r for _, r in records if len(r["free"]) > i]
        row: dict[str, Any] = {"round": i + 1, "n": len(have)}
        for k in kinds:
            mses = {v: float(np.mean([r[k][i][v] for r in have])) for v in views}
            psnrs = {v: _psnr(m) for v, m in mses.items()}
            psnrs["all"] = _psnr(float(np.mean(list(mses.values()))))
            row[k] = psnrs
            for v, p in psnrs.items():
                per_view[v][k].append(p)
        row["compounding_db"] = round(row["teacher_forced"]["all"] - row["free"]["all"], 3)
        row["tf_gain_over_frozen_head_db"] = (
            round(row["teacher_forced"][HEAD] - row["frozen"][HEAD], 3) if HEAD in views else None
        )
        rows.append(row)
    return {
        "n": len(records),
        "metric": "pooled PSNR (dB) over the round's K frames of every pair",
        "rounds": rows,
        "head": per_view.get(HEAD, {}),
        "all_views": per_view["all"],
    }


# ---------------------------------------------------------------------- the ladder


def run_wm_ladder(cfg: LadderConfig, *, progress: bool = True) -> dict[str, Any]:
    """Run (or resume) the rungs of ``cfg``; returns the JSON-friendly result (see the module doc)."""
    t_start = time.monotonic()
    lab = Lab(cfg)
    plan = cfg.plan()
    result: dict[str, Any] = {
        "bench": "wm-ladder",
        "quick": cfg.quick,
        "model": str(lab.model_path),
        "rig": str(cfg.rig),
        "tasks": list(cfg.tasks),
        "checkpoints": list(cfg.checkpoint_names),
        "subtasks_per_setting": cfg.subtasks_per_setting,
        "n_pairs": len(plan),
        "seeds": {
            "layout_seed0": cfg.seed0,
            "layout_seeds": sorted({p.subtask.seed for p in plan}),
            "policy_and_model_seed": "layout_seed * 100 + subtask_index (the paired runner's pair seed)",
        },
        "spec": dataclasses.asdict(cfg.spec),
        "rungs": list(cfg.rungs),
        "out": str(lab.out),
        "skipped": {},
        "seconds": {},
    }
    try:
        model, _, resized = lab.model(cfg.tasks[0])  # a bad model fails before anything runs
        result["model_resized"] = resized
        result["adapters"] = {t: lab.model(t)[1] for t in cfg.tasks} if set(cfg.rungs) - {"state_contract"} else None
        ae = autoencoder_for(model)
        views = list(model.info.views)
        for rung in cfg.rungs:
            t0 = time.monotonic()
            runs0 = lab.real_runs
            if rung == "state_contract":
                recs = _each(
                    lab, rung, {"real": lab.real_key}, plan, lambda p, i: state_contract_record(lab, p, i), progress
                )
                result[rung] = state_contract_summary(recs)
            elif rung == "representation":
                if isinstance(ae, str):
                    result[rung] = None
                    result["skipped"][rung] = ae
                    continue
                recs = _each(
                    lab, rung, {"model": lab.model_key}, plan, lambda p, i: representation_record(lab, p, i), progress
                )
                result[rung] = representation_summary(recs)
            elif rung == "judge_fairness":
                degr = [d for d in DEGRADATIONS if d != "autoencoded" or isinstance(ae, FrameAutoencoder)]
                if isinstance(ae, str):
                    result["skipped"]["judge_fairness.autoencoded"] = ae
                key = {"model": lab.model_key if isinstance(ae, FrameAutoencoder) else lab.real_key, "d": degr}
                recs = _each(lab, rung, key, plan, partial(judge_fairness_record, lab, degradations=degr), progress)
                result[rung] = judge_fairness_summary(recs, degr)
                if isinstance(ae, str):
                    result[rung]["autoencoded"] = None
            elif rung == "teacher_forced":
                recs = _each(
                    lab, rung, {"model": lab.model_key}, plan, lambda p, i: teacher_forced_record(lab, p, i), progress
                )
                result[rung] = teacher_forced_summary(recs, views)
            result[rung]["seeds"] = result["seeds"]["layout_seeds"]
            result[rung]["real_branches_run"] = lab.real_runs - runs0
            result["seconds"][rung] = round(time.monotonic() - t0, 1)
            write_json(lab.out / f"{rung}.json", result[rung], durable=False)
    finally:
        lab.close()
    result["wall_seconds"] = round(time.monotonic() - t_start, 1)
    result["machine"] = {**machine_info(), "torch_threads": torch.get_num_threads()}
    write_json(lab.out / "ladder.json", result, durable=False)
    return result


def summary_lines(r: dict[str, Any]) -> list[str]:
    """The human summary the CLI prints above the JSON."""

    def pct(x: Any) -> str:
        return "-" if x is None else f"{100 * x:.0f}%"

    def ci(x: Any) -> str:
        return "" if not x else f" [{100 * x[0]:.0f}, {100 * x[1]:.0f}]"

    lines = [
        f"wm-ladder ({'quick' if r['quick'] else 'full'}): {r['n_pairs']} pairs, model {r['model']}, "
        f"{r['wall_seconds']} s"
    ]
    s = r.get("state_contract")
    if s:
        lines.append(
            "  0 state contract  SR " + ", ".join(f"{m} {pct(s['sr'][m])}{ci(s['sr_ci95'][m])}" for m in s["modes"])
        )
    if "representation" in r:
        rep = r["representation"]
        if rep is None:
            lines.append(f"  1 representation  skipped: {r['skipped'].get('representation')}")
        else:
            j = rep["judges"]
            lines.append(
                f"  1 representation  SR real {pct(rep['sr']['real'])}, autoencoded {pct(rep['sr']['autoencoded'])}; "
                f"judge agreement plain {pct(j['plain']['agreement'])} / AE {pct(j['autoencoded']['agreement'])}, "
                f"hallucination FP plain {pct(j['plain']['hallucination_fp_rate'])} / AE "
                f"{pct(j['autoencoded']['hallucination_fp_rate'])}; AE PSNR {rep['autoencoder_psnr']}"
            )
    jf = r.get("judge_fairness")
    if jf:
        parts = [
            f"{d}: agree {pct(jf[d]['agreement'])} FP {pct(jf[d]['hallucination_fp_rate'])} "
            f"recall {pct(jf[d]['fault_recall'])}"
            for d in jf["degradations"]
        ]
        lines.append("  2 judge fairness  " + "; ".join(parts))
    tf = r.get("teacher_forced")
    if tf:
        lines.append("  3 teacher forced  round    " + "".join(f"{row['round']:>7}" for row in tf["rounds"]))
        for k in ("teacher_forced", "free", "frozen", "frozen_start"):
            lines.append(f"    head PSNR {k:<14}" + "".join(f"{row[k][HEAD]:>7.2f}" for row in tf["rounds"]))
    return lines
