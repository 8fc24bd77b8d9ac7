"""The world-model contract: one interface for every backend (our native model, Wan2.1, the frozen baseline).

A world model predicts the next K frames of every view from the current frame of every view, the
H_h history frames of every view (real at the start of a rollout, generated later), the head-view
control video Γ(A) of the chunk's stride-aligned actions, and the instruction (paper §3.2, DESIGN.md).

Two levels:

* :class:`PredictRequest` — one sample as numpy arrays, validated on construction with ``ValueError``
  naming the problem (wrong views, wrong image size, NaN actions, …). The imagined branch uses it.
* :class:`WorldModelBatch` — a batch of tensors, the shape a training clip has (see
  :class:`pilworld.data.clip_dataset.ClipDataset` plus ``control``). Training and benchmarks use it.

Images are uint8 RGB everywhere at the boundary; backends convert to their own range inside.

Every model offers :class:`WorldModel`. Some offer more, each an optional capability with a protocol of
its own that a caller queries with ``isinstance`` (the protocols are runtime-checkable), never by probing
attribute names:

* :class:`RigBound` — the model composites the rig's geometry (world model v2): ``bind_rig(rig)`` makes it
  use this rig's robot model and camera calibration;
* :class:`StatefulRollout` — the model carries state across the chunks of one rollout (v2: its tracked
  objects), started by ``begin_rollout`` at the imagined branch's reset;
* :class:`StatePrediction` — ``predict_with_state`` also predicts the joint state the robot will report (v2);
* :class:`HistoryAblation` — the model can run with its history memory hidden (``without_history``), the
  paper's no-history ablation.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any, Protocol, runtime_checkable

import numpy as np
import torch
from numpy.typing import NDArray

from pilworld.types import STATE_DIM

if TYPE_CHECKING:
    from pilworld.config.rig import RigConfig
    from pilworld.control_video.robot_model import RobotModel


@dataclass(frozen=True)
class WorldModelInfo:
    """What a world model expects: views (in order), image size, K and H_h."""

    views: tuple[str, ...]  # camera keys; the head view (which the control video shows) first
    height: int  # image rows
    width: int  # image columns
    future: int  # K frames predicted per call
    history: int  # H_h history frames per view
    action_dim: int = STATE_DIM  # stride-aligned action width (only the action-token ablation reads it)

    def __post_init__(self) -> None:
        if not self.views or len(set(self.views)) != len(self.views):
            raise ValueError(f"views: expected distinct camera keys, got {self.views!r}")
        for name in ("height", "width", "future"):
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, int) or v < 1:
                raise ValueError(f"{name}: expected an integer >= 1, got {v!r}")
        if isinstance(self.history, bool) or not isinstance(self.history, int) or self.history < 0:
            raise ValueError(f"history: expected an integer >= 0, got {self.history!r}")


def _check_frames(name: str, value: Any, shape: tuple[int, ...]) -> NDArray[np.uint8]:
    arr = np.asarray(value)
    if arr.dtype != np.uint8:
        raise ValueError(f"{name}: expected uint8 RGB frames, got dtype {arr.dtype}")
    if arr.shape != shape:
        raise ValueError(f"{name}: expected shape {shape}, got {arr.shape} (wrong image size or frame count?)")
    return arr


@dataclass(frozen=True)
class PredictRequest:
    """One world-model call, validated against a model's :class:`WorldModelInfo` by :meth:`build`."""

    current: Mapping[str, NDArray[np.uint8]]  # view -> [H, W, 3]
    history: Mapping[str, NDArray[np.uint8]]  # view -> [H_h, H, W, 3], oldest first
    history_valid: NDArray[np.bool_]  # [H_h]; False where a frame precedes the episode (a repeat of frame 0)
    control: NDArray[np.uint8]  # [K, H, W, 3] head-view control video Γ(A)
    actions: NDArray[np.float32]  # [K, action_dim] stride-aligned actions
    instruction: str
    # [STATE_DIM] the joint state the chunk starts from (measured, or predicted by the model last round);
    # world models that composite geometry (v2) need it, the others ignore it
    state: NDArray[np.float32] | None = None
    history_state: NDArray[np.float32] | None = None  # [H_h, STATE_DIM] the joint state of each history frame

    @classmethod
    def build(
        cls,
        info: WorldModelInfo,
        *,
        current: Mapping[str, Any],
        history: Mapping[str, Any] | None,
        control: Any,
        actions: Any,
        instruction: str,
        history_valid: Sequence[bool] | NDArray[np.bool_] | None = None,
        state: Any = None,
        history_state: Any = None,
    ) -> PredictRequest:
        """Validate every input against ``info``; ``history=None`` repeats the current frame (all invalid)."""
        H, W, K, Hh = info.height, info.width, info.future, info.history
        for what, got in (("current", current), ("history", history)):
            if got is None:
                continue
            if set(got) != set(info.views):
                missing = sorted(set(info.views) - set(got))
                extra = sorted(set(got) - set(info.views))
                raise ValueError(
                    f"{what}: views do not match the world model's {list(info.views)} "
                    f"(missing {missing}, unexpected {extra})"
                )
        cur = {v: _check_frames(f"current[{v!r}]", current[v], (H, W, 3)) for v in info.views}
        if history is None:
            hist = {v: np.repeat(cur[v][None], Hh, axis=0) for v in info.views}
            valid = np.zeros(Hh, dtype=bool)
        else:
            hist = {v: _check_frames(f"history[{v!r}]", history[v], (Hh, H, W, 3)) for v in info.views}
            valid = np.ones(Hh, dtype=bool) if history_valid is None else np.asarray(history_valid, dtype=bool)
            if valid.shape != (Hh,):
                raise ValueError(f"history_valid: expected shape ({Hh},), got {valid.shape}")
        ctrl = _check_frames("control", control, (K, H, W, 3))
        act = np.asarray(actions)
        if not np.issubdtype(act.dtype, np.number):
            raise ValueError(f"actions: expected numbers, got dtype {act.dtype}")
        act = act.astype(np.float32)
        if act.shape != (K, info.action_dim):
            raise ValueError(
                f"actions: expected stride-aligned actions of shape ({K}, {info.action_dim}), got {act.shape}"
            )
        if not np.all(np.isfinite(act)):
            bad = np.argwhere(~np.isfinite(act))[0]  # float(): numpy 2 would print np.float32(nan)
            raise ValueError(
                f"actions: non-finite value {float(act[tuple(bad)])} at index {tuple(int(i) for i in bad)}"
            )
        if not isinstance(instruction, str):
            raise ValueError(f"instruction: expected a string, got {type(instruction).__name__}")
        st = None
        if state is not None:
            st = np.asarray(state, dtype=np.float32)
            if st.shape != (STATE_DIM,) or not np.all(np.isfinite(st)):
                raise ValueError(f"state: expected {STATE_DIM} finite joint values, got shape {st.shape}")
        hst = None
        if history_state is not None:
            hst = np.asarray(history_state, dtype=np.float32)
            if hst.shape != (Hh, STATE_DIM) or not np.all(np.isfinite(hst)):
                raise ValueError(f"history_state: expected ({Hh}, {STATE_DIM}) finite joint values, got {hst.shape}")
        return cls(cur, hist, valid, ctrl, act, instruction, st, hst)

    def to_batch(self, views: Sequence[str]) -> WorldModelBatch:
        def t(x: NDArray[np.uint8]) -> torch.Tensor:  # [..., H, W, 3] -> [..., 3, H, W]
            return torch.from_numpy(np.ascontiguousarray(np.moveaxis(x, -1, -3)))

        return WorldModelBatch(
            current=t(np.stack([self.current[v] for v in views]))[None],
            history=t(np.stack([self.history[v] for v in views]))[None],
            history_valid=torch.from_numpy(self.history_valid.copy())[None],
            control=t(self.control)[None],
            actions=torch.from_numpy(self.actions.copy())[None],
            instruction=[self.instruction],
            state=None if self.state is None else torch.from_numpy(self.state.copy())[None],
        )


@dataclass
class WorldModelBatch:
    """A batch of world-model inputs (uint8 images, channels first)."""

    current: torch.Tensor  # uint8 [B, V, 3, H, W]
    history: torch.Tensor  # uint8 [B, V, H_h, 3, H, W]
    history_valid: torch.Tensor  # bool [B, H_h]
    control: torch.Tensor  # uint8 [B, K, 3, H, W] head view
    actions: torch.Tensor  # float32 [B, K, action_dim]
    instruction: list[str]  # B strings
    future: torch.Tensor | None = None  # uint8 [B, V, K, 3, H, W] ground truth (training and benchmarks)
    state: torch.Tensor | None = None  # float32 [B, STATE_DIM] joint state at the current frame

    @property
    def size(self) -> int:
        return int(self.current.shape[0])

    def to(self, device: torch.device | str) -> WorldModelBatch:
        return WorldModelBatch(
            self.current.to(device),
            self.history.to(device),
            self.history_valid.to(device),
            self.control.to(device),
            self.actions.to(device),
            list(self.instruction),
            None if self.future is None else self.future.to(device),
            None if self.state is None else self.state.to(device),
        )

    def check(self, info: WorldModelInfo) -> None:
        """Raise ``ValueError`` naming the first field whose shape or dtype does not fit ``info``."""
        B, V, K, Hh, H, W = self.size, len(info.views), info.future, info.history, info.height, info.width
        want: dict[str, tuple[torch.Tensor | None, tuple[int, ...], torch.dtype]] = {
            "current": (self.current, (B, V, 3, H, W), torch.uint8),
            "history": (self.history, (B, V, Hh, 3, H, W), torch.uint8),
            "history_valid": (self.history_valid, (B, Hh), torch.bool),
            "control": (self.control, (B, K, 3, H, W), torch.uint8),
            "actions": (self.actions, (B, K, info.action_dim), torch.float32),
            "future": (self.future, (B, V, K, 3, H, W), torch.uint8),
        }
        for name, (x, shape, dtype) in want.items():
            if x is None:
                continue
            if tuple(x.shape) != shape:
                raise ValueError(f"{name}: expected shape {shape}, got {tuple(x.shape)}")
            if x.dtype != dtype:
                raise ValueError(f"{name}: expected dtype {dtype}, got {x.dtype}")
        if not torch.isfinite(self.actions).all():
            raise ValueError("actions: contains non-finite values")
        if len(self.instruction) != B:
            raise ValueError(f"instruction: expected {B} strings, got {len(self.instruction)}")


@runtime_checkable
class WorldModel(Protocol):
    """Predicts K frames of every view; see the module docstring."""

    @property
    def info(self) -> WorldModelInfo: ...

    def predict_batch(self, batch: WorldModelBatch, *, steps: int | None = None, seed: int = 0) -> torch.Tensor:
        """uint8 [B, V, K, 3, H, W] predicted future frames (views in ``info.views`` order)."""
        ...

    def predict(
        self, request: PredictRequest, *, steps: int | None = None, seed: int = 0
    ) -> dict[str, NDArray[np.uint8]]:
        """One sample: view -> uint8 [K, H, W, 3]."""
        ...


@runtime_checkable
class RigBound(Protocol):
    """A world model that composites the rig's geometry; bound to the rig it runs on before a rollout."""

    def bind_rig(self, rig: RigConfig, *, robot: RobotModel | None = None) -> None:
        """Use ``rig``'s robot model and cameras (``robot``: render this robot model instead)."""
        ...


@runtime_checkable
class StatefulRollout(Protocol):
    """A world model that carries state across one rollout's chunks, started at the imagined branch's reset."""

    def begin_rollout(
        self, current: dict[str, NDArray[np.uint8]], state: NDArray[np.floating], instruction: str
    ) -> None:
        """Start a rollout from its first frames (view -> uint8 [H, W, 3]) and joint state."""
        ...


@runtime_checkable
class StatePrediction(Protocol):
    """A world model that also predicts the joint state the robot will report (e.g. a gripper resting on what
    it holds); without it, the state after a chunk is its last stride-aligned action."""

    def predict_with_state(
        self, request: PredictRequest, *, steps: int | None = None, seed: int = 0
    ) -> tuple[dict[str, NDArray[np.uint8]], NDArray[np.float32]]:
        """One chunk: view -> uint8 [K, H, W, 3], and the [K, STATE_DIM] state the robot will report."""
        ...


@runtime_checkable
class HistoryAblation(Protocol):
    """A world model that can run with its history memory hidden (the no-history ablation)."""

    def without_history(self) -> WorldModel:
        """The same model, ignoring every history frame."""
        ...


def predict_one(
    model: WorldModel, request: PredictRequest, *, steps: int | None = None, seed: int = 0
) -> dict[str, NDArray[np.uint8]]:
    """The shared ``predict`` of every backend: one request through ``predict_batch``."""
    out = model.predict_batch(request.to_batch(model.info.views), steps=steps, seed=seed)[0]  # [V, K, 3, H, W]
    frames = out.permute(0, 1, 3, 4, 2).contiguous().cpu().numpy()
    return {v: frames[i] for i, v in enumerate(model.info.views)}


class FrozenWorldModel:
    """The copy-the-current-frame baseline: every future frame equals the current one (``psnr_frozen``)."""

    def __init__(self, info: WorldModelInfo) -> None:
        self._info = info

    @property
    def info(self) -> WorldModelInfo:
        return self._info

    def predict_batch(self, batch: WorldModelBatch, *, steps: int | None = None, seed: int = 0) -> torch.Tensor:
        batch.check(self._info)
        return batch.current[:, :, None].expand(-1, -1, self._info.future, -1, -1, -1).clone()

    def predict(
        self, request: PredictRequest, *, steps: int | None = None, seed: int = 0
    ) -> dict[str, NDArray[np.uint8]]:
        return predict_one(self, request, steps=steps, seed=seed)
