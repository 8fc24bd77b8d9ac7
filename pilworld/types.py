"""The data contract shared by both branches: observations, action chunks, segments, subtasks, robot specs.

Everything that crosses a boundary (robot → policy, policy → env, env → store) is one of these types.
Constructors validate shape, dtype and finiteness and raise ``ValueError`` naming the field and the bad
value, so a malformed frame is caught where it is made rather than deep inside a model.

Conventions (see ``shared/DESIGN.md``):

* state and action vectors are 14-d ``[L j1..j6, L grip, R j1..j6, R grip]``: joints absolute radians,
  grip normalised 0 = closed … 1 = open;
* images are ``uint8[H, W, 3]`` RGB, one per camera key (``cam_high``, ``cam_left_wrist``, …);
* an action chunk ``A = a_{t+1..t+H_π}`` is stored 0-based, so the paper's stride-aligned actions
  ``a_{t+Δ}, …, a_{t+KΔ}`` are rows ``Δ-1, 2Δ-1, …, KΔ-1``.
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from types import MappingProxyType
from typing import Any

import numpy as np
from numpy.typing import NDArray

# The dual-arm layout of state and action vectors (ALOHA / openpi order).
STATE_DIM = 14
LEFT_ARM = slice(0, 6)
LEFT_GRIP = 6
RIGHT_ARM = slice(7, 13)
RIGHT_GRIP = 13
ARM_SIDES = ("left", "right")
# Per arm: (its joints, its grip) in the 14-d vector.
ARM_LAYOUT: Mapping[str, tuple[slice, int]] = MappingProxyType(
    {"left": (LEFT_ARM, LEFT_GRIP), "right": (RIGHT_ARM, RIGHT_GRIP)}
)
DEFAULT_VIEWS = ("cam_high", "cam_left_wrist", "cam_right_wrist")
HEAD_VIEW = "cam_high"


def _describe(value: Any) -> str:
    """A short description of a bad value for error messages (never the whole array)."""
    if isinstance(value, np.ndarray):
        return f"array(shape={value.shape}, dtype={value.dtype})"
    text = repr(value)
    return text if len(text) <= 80 else text[:77] + "..."


def _first_non_finite(arr: NDArray[Any]) -> str:
    bad = np.argwhere(~np.isfinite(arr))[0]
    index = tuple(int(i) for i in bad)
    return f"{arr[index].item()!r} at index {index if len(index) > 1 else index[0]}"


def check_float_array(
    name: str, value: Any, *, dtype: type[np.floating[Any]], shape: tuple[int | None, ...]
) -> NDArray[Any]:
    """Validate a finite float array of the given dtype and shape (``None`` = any length).

    The array must already have ``dtype``: silently casting float64 → float32 would hide a caller that
    mixes precisions, so use the ``from_*`` constructors when a cast is intended.
    """
    if not isinstance(value, np.ndarray):
        raise ValueError(f"{name}: expected a numpy array, got {_describe(value)}")
    if value.dtype != dtype:
        raise ValueError(f"{name}: expected dtype {np.dtype(dtype).name}, got {value.dtype}")
    if value.ndim != len(shape) or any(s is not None and s != n for s, n in zip(shape, value.shape, strict=True)):
        want = "×".join("N" if s is None else str(s) for s in shape)
        raise ValueError(f"{name}: expected shape ({want}), got {value.shape}")
    if not np.all(np.isfinite(value)):
        raise ValueError(f"{name}: values must be finite, got {_first_non_finite(value)}")
    return value


def _frozen(arr: NDArray[Any]) -> NDArray[Any]:
    out = np.array(arr, copy=True)
    out.flags.writeable = False
    return out


def check_image(name: str, value: Any) -> NDArray[np.uint8]:
    """Validate one RGB image: ``uint8[H, W, 3]`` with H, W > 0."""
    if not isinstance(value, np.ndarray):
        raise ValueError(f"{name}: expected a numpy uint8 array of shape (H, W, 3), got {_describe(value)}")
    if value.dtype != np.uint8:
        raise ValueError(f"{name}: expected dtype uint8, got {value.dtype}")
    if value.ndim != 3 or value.shape[2] != 3 or value.shape[0] == 0 or value.shape[1] == 0:
        raise ValueError(f"{name}: expected shape (H, W, 3) with H, W > 0, got {value.shape}")
    return value


@dataclass(frozen=True, eq=False)
class Observation:
    """One multi-view observation: ``images[view]`` uint8[H, W, 3] RGB, ``state`` float32[D], time.

    ``timestamp`` is monotonic seconds (``time.monotonic()`` on a robot, simulated time in the sim,
    frame time in the imagined branch). Arrays are stored as read-only copies, so an observation cannot
    change after a policy has seen it.
    """

    images: Mapping[str, NDArray[np.uint8]]
    state: NDArray[np.float32]
    timestamp: float

    def __post_init__(self) -> None:
        if not isinstance(self.images, Mapping) or not self.images:
            raise ValueError(f"images: expected a non-empty mapping view -> image, got {_describe(self.images)}")
        frozen: dict[str, NDArray[np.uint8]] = {}
        for view, image in self.images.items():
            if not isinstance(view, str) or not view:
                raise ValueError(f"images: view names must be non-empty strings, got {view!r}")
            frozen[view] = _frozen(check_image(f"images[{view!r}]", image))
        object.__setattr__(self, "images", MappingProxyType(frozen))
        state = check_float_array("state", self.state, dtype=np.float32, shape=(None,))
        object.__setattr__(self, "state", _frozen(state))
        if isinstance(self.timestamp, bool) or not isinstance(self.timestamp, int | float):
            raise ValueError(f"timestamp: expected a number of seconds, got {_describe(self.timestamp)}")
        if not math.isfinite(self.timestamp):
            raise ValueError(f"timestamp: must be finite, got {self.timestamp!r}")
        object.__setattr__(self, "timestamp", float(self.timestamp))

    @classmethod
    def from_raw(cls, images: Mapping[str, Any], state: Any, timestamp: float) -> Observation:
        """Build from loosely typed input: the state is cast to float32 (after checking it is numeric)."""
        state_arr = np.asarray(state)
        if not np.issubdtype(state_arr.dtype, np.number):
            raise ValueError(f"state: expected numbers, got dtype {state_arr.dtype}")
        return cls(images=dict(images), state=state_arr.astype(np.float32), timestamp=timestamp)

    @property
    def views(self) -> tuple[str, ...]:
        return tuple(self.images)

    def image_size(self, view: str) -> tuple[int, int]:
        """(width, height) of one view."""
        image = self.images[view]
        return int(image.shape[1]), int(image.shape[0])


@dataclass(frozen=True)
class ChunkSpec:
    """The chunk timing of the paper (§3.1): H_π actions per query, K frames at stride Δ per round.

    Only the first ``K·Δ`` steps of each chunk are executed in both branches; the rest are dropped and
    the policy is queried again.
    """

    horizon: int = 50  # H_π: actions per policy query
    frames: int = 15  # K: frames predicted (real branch: recorded) per round
    stride: int = 3  # Δ: control steps between consecutive frames
    history: int = 5  # H_h: history frames kept in the world model's memory
    rounds: int = 5  # R: closed-loop rounds per subtask

    def __post_init__(self) -> None:
        for name in ("horizon", "frames", "stride", "rounds"):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, int) or value < 1:
                raise ValueError(f"{name}: expected an integer >= 1, got {value!r}")
        if isinstance(self.history, bool) or not isinstance(self.history, int) or self.history < 0:
            raise ValueError(f"history: expected an integer >= 0, got {self.history!r}")
        if self.frames * self.stride > self.horizon:
            raise ValueError(
                f"frames × stride must not exceed horizon (K·Δ ≤ H_π): "
                f"{self.frames} × {self.stride} = {self.executed_steps} > {self.horizon}"
            )

    @property
    def executed_steps(self) -> int:
        """K·Δ: control steps executed per round."""
        return self.frames * self.stride

    def stride_indices(self) -> NDArray[np.intp]:
        """0-based rows of the stride-aligned actions ``a_{t+Δ}, …, a_{t+KΔ}``: Δ-1, 2Δ-1, …, KΔ-1."""
        return np.arange(1, self.frames + 1, dtype=np.intp) * self.stride - 1


@dataclass(frozen=True, eq=False)
class ActionChunk:
    """A policy's action chunk ``float32[H_π, D]`` of absolute commands (joints rad, grips 0..1)."""

    actions: NDArray[np.float32]

    def __post_init__(self) -> None:
        actions = check_float_array("actions", self.actions, dtype=np.float32, shape=(None, None))
        if actions.shape[0] == 0 or actions.shape[1] == 0:
            raise ValueError(f"actions: expected a non-empty (H, D) array, got shape {actions.shape}")
        object.__setattr__(self, "actions", _frozen(actions))

    @classmethod
    def from_array(cls, actions: Any, *, name: str = "actions") -> ActionChunk:
        """Cast any numeric (H, D) array (openpi replies are not guaranteed float32) to a chunk."""
        arr = np.asarray(actions)
        if not np.issubdtype(arr.dtype, np.number) or np.issubdtype(arr.dtype, np.complexfloating):
            raise ValueError(f"{name}: expected real numbers, got dtype {arr.dtype}")
        try:
            return cls(arr.astype(np.float32))
        except ValueError as err:
            raise ValueError(str(err).replace("actions:", f"{name}:", 1)) from None

    @property
    def horizon(self) -> int:
        return int(self.actions.shape[0])

    @property
    def dim(self) -> int:
        return int(self.actions.shape[1])

    def _require(self, spec: ChunkSpec) -> None:
        if self.horizon < spec.executed_steps:
            raise ValueError(
                f"actions: chunk has {self.horizon} steps but K·Δ = {spec.frames}·{spec.stride} = "
                f"{spec.executed_steps} are needed"
            )

    def stride_aligned(self, spec: ChunkSpec) -> NDArray[np.float32]:
        """The K stride-aligned actions ``a_{t+Δ}, …, a_{t+KΔ}`` as float32[K, D] (paper §3.1)."""
        self._require(spec)
        return self.actions[spec.stride_indices()]

    def executed(self, spec: ChunkSpec) -> NDArray[np.float32]:
        """The first K·Δ steps, the ones both branches execute, float32[K·Δ, D]."""
        self._require(spec)
        return self.actions[: spec.executed_steps]


@dataclass(frozen=True, eq=False)
class Segment:
    """What one round of either branch produced: K observations at stride Δ and the K·Δ executed steps.

    ``actions[i]`` is what was actually commanded at step i (after the safety filter on a robot, the
    chunk itself in the imagined branch); ``observations[k]`` is the observation after step (k+1)·Δ.
    """

    observations: tuple[Observation, ...]
    actions: NDArray[np.float32]
    stride: int

    def __post_init__(self) -> None:
        obs = tuple(self.observations)
        if not obs or not all(isinstance(o, Observation) for o in obs):
            raise ValueError(
                f"observations: expected a non-empty sequence of Observation, got {_describe(self.observations)}"
            )
        object.__setattr__(self, "observations", obs)
        if isinstance(self.stride, bool) or not isinstance(self.stride, int) or self.stride < 1:
            raise ValueError(f"stride: expected an integer >= 1, got {self.stride!r}")
        actions = check_float_array("actions", self.actions, dtype=np.float32, shape=(None, None))
        if actions.shape[0] != len(obs) * self.stride:
            raise ValueError(
                f"actions: expected {len(obs)} observations × stride {self.stride} = "
                f"{len(obs) * self.stride} rows, got {actions.shape[0]}"
            )
        object.__setattr__(self, "actions", _frozen(actions))
        stamps = [o.timestamp for o in obs]
        if any(b < a for a, b in itertools.pairwise(stamps)):
            raise ValueError(f"observations: timestamps must not decrease, got {stamps}")

    @property
    def last(self) -> Observation:
        """The terminal observation, fed back to the policy for the next round."""
        return self.observations[-1]


@dataclass(frozen=True)
class Subtask:
    """One evaluation unit: a task, which of its subtasks, the instruction and the layout seed."""

    task: str  # registered task name, e.g. "sort_cubes"
    index: int  # 0-based subtask index within the task
    instruction: str  # the language instruction given to the policy
    seed: int = 0  # layout seed (simulated rig) or trial number (real rig)

    def __post_init__(self) -> None:
        if not isinstance(self.task, str) or not self.task.strip():
            raise ValueError(f"task: expected a non-empty task name, got {self.task!r}")
        if isinstance(self.index, bool) or not isinstance(self.index, int) or self.index < 0:
            raise ValueError(f"index: expected an integer >= 0, got {self.index!r}")
        if not isinstance(self.instruction, str) or not self.instruction.strip():
            raise ValueError(f"instruction: expected a non-empty string, got {self.instruction!r}")
        if isinstance(self.seed, bool) or not isinstance(self.seed, int):
            raise ValueError(f"seed: expected an integer, got {self.seed!r}")


@dataclass(frozen=True)
class Start:
    """The shared start of both branches: the subtask, its first observation and the history before it.

    ``history`` holds up to H_h earlier observations at stride Δ, oldest first (real frames; the world
    model's latent memory starts from them).
    """

    subtask: Subtask
    observation: Observation
    history: tuple[Observation, ...] = ()

    def __post_init__(self) -> None:
        if not isinstance(self.subtask, Subtask):
            raise ValueError(f"subtask: expected a Subtask, got {_describe(self.subtask)}")
        if not isinstance(self.observation, Observation):
            raise ValueError(f"observation: expected an Observation, got {_describe(self.observation)}")
        history = tuple(self.history)
        for i, h in enumerate(history):
            if not isinstance(h, Observation):
                raise ValueError(f"history[{i}]: expected an Observation, got {_describe(h)}")
            if set(h.views) != set(self.observation.views):
                raise ValueError(
                    f"history[{i}]: views {sorted(h.views)} differ from the observation's "
                    f"{sorted(self.observation.views)}"
                )
            if h.timestamp > self.observation.timestamp:
                raise ValueError(
                    f"history[{i}]: timestamp {h.timestamp} is after the start observation's "
                    f"{self.observation.timestamp}"
                )
        object.__setattr__(self, "history", history)


@dataclass(frozen=True)
class RobotSpec:
    """What a robot (real, simulated or imagined) exposes: joints, limits, cameras, control rate."""

    joint_names: tuple[str, ...]
    lower: tuple[float, ...]  # per joint; radians for arm joints, 0 for grips
    upper: tuple[float, ...]  # per joint; radians for arm joints, 1 for grips
    cameras: tuple[str, ...] = DEFAULT_VIEWS
    control_rate_hz: float = 30.0
    image_size: tuple[int, int] = (128, 128)  # (width, height) of every camera
    max_joint_speed: tuple[float, ...] = field(default=())  # rad/s (grips: 1/s); () = unlimited

    def __post_init__(self) -> None:
        n = len(self.joint_names)
        if n == 0 or len(set(self.joint_names)) != n:
            raise ValueError(f"joint_names: expected unique non-empty names, got {self.joint_names!r}")
        for name in ("lower", "upper"):
            values = getattr(self, name)
            if len(values) != n or not all(math.isfinite(float(v)) for v in values):
                raise ValueError(f"{name}: expected {n} finite values (one per joint), got {values!r}")
        bad = [j for j, lo, hi in zip(self.joint_names, self.lower, self.upper, strict=True) if not lo < hi]
        if bad:
            raise ValueError(f"lower/upper: lower must be < upper for every joint, not for {bad}")
        if self.max_joint_speed and (len(self.max_joint_speed) != n or not all(v > 0 for v in self.max_joint_speed)):
            raise ValueError(f"max_joint_speed: expected {n} positive values or (), got {self.max_joint_speed!r}")
        if not self.cameras or len(set(self.cameras)) != len(self.cameras):
            raise ValueError(f"cameras: expected unique non-empty camera keys, got {self.cameras!r}")
        if not (math.isfinite(self.control_rate_hz) and self.control_rate_hz > 0):
            raise ValueError(f"control_rate_hz: expected a positive rate, got {self.control_rate_hz!r}")
        w, h = self.image_size
        if w < 1 or h < 1:
            raise ValueError(f"image_size: expected positive (width, height), got {self.image_size!r}")

    @property
    def dof(self) -> int:
        return len(self.joint_names)

    @property
    def lower_array(self) -> NDArray[np.float32]:
        return np.asarray(self.lower, dtype=np.float32)

    @property
    def upper_array(self) -> NDArray[np.float32]:
        return np.asarray(self.upper, dtype=np.float32)

    def check_state(self, name: str, vector: NDArray[np.float32]) -> None:
        """Raise ``ValueError`` naming ``name`` if a state/action vector does not fit this robot."""
        check_float_array(name, vector, dtype=np.float32, shape=(self.dof,))

    def out_of_limits(self, vector: NDArray[np.float32]) -> list[str]:
        """Names of the joints whose value lies outside [lower, upper]."""
        outside = (vector < self.lower_array) | (vector > self.upper_array)
        return [self.joint_names[i] for i in np.flatnonzero(outside)]


def dual_arm_joint_names(prefixes: Sequence[str] = ARM_SIDES) -> tuple[str, ...]:
    """``left_joint_1 … left_joint_6, left_grip, right_joint_1 …`` in the 14-d vector's order."""
    names: list[str] = []
    for side in prefixes:
        names += [f"{side}_joint_{i}" for i in range(1, 7)]
        names.append(f"{side}_grip")
    return tuple(names)
