"""One recorded episode in memory: per-view frames, state, action and the PiL-World labels."""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import NDArray

from pilworld.data.spec import ORIGINS, DatasetSpec
from pilworld.types import check_float_array


@dataclass(frozen=True, eq=False)
class Episode:
    """``T`` frames of one episode. Row ``i`` of every array is frame ``i`` (time ``i / fps``).

    ``round_index[i]`` is the closed-loop round frame ``i`` belongs to (0 for plain demonstrations).
    """

    images: Mapping[str, NDArray[np.uint8]]  # view → uint8 (T, H, W, 3) RGB
    state: NDArray[np.float32]  # (T, state_dim)
    action: NDArray[np.float32]  # (T, action_dim): the command sent at frame i
    task: str  # the language instruction
    origin: str = "real"  # real | imagined
    subtask_index: int = 0
    checkpoint: str = ""  # policy checkpoint that produced the actions ("" for teleoperation)
    seed: int = 0
    round_index: NDArray[np.int64] | None = None  # (T,); None = all zeros
    extra: dict[str, Any] = field(default_factory=dict)  # free-form, stored in the episodes table as JSON

    @property
    def length(self) -> int:
        return int(self.state.shape[0])

    def rounds(self) -> NDArray[np.int64]:
        if self.round_index is None:
            return np.zeros(self.length, dtype=np.int64)
        return self.round_index

    def check(self, spec: DatasetSpec) -> None:
        """Raise ``ValueError`` naming the field if this episode does not fit ``spec``."""
        state = check_float_array("state", self.state, dtype=np.float32, shape=(None, spec.state_dim))
        T = state.shape[0]
        if T == 0:
            raise ValueError("state: an episode needs at least one frame")
        check_float_array("action", self.action, dtype=np.float32, shape=(T, spec.action_dim))
        if set(self.images) != set(spec.views):
            raise ValueError(f"images: expected views {sorted(spec.views)}, got {sorted(self.images)}")
        for view, frames in self.images.items():
            h, w = spec.views[view]
            if not isinstance(frames, np.ndarray) or frames.dtype != np.uint8 or frames.shape != (T, h, w, 3):
                got = (frames.dtype, frames.shape) if isinstance(frames, np.ndarray) else type(frames).__name__
                raise ValueError(f"images[{view!r}]: expected uint8 ({T}, {h}, {w}, 3), got {got}")
        if not isinstance(self.task, str) or not self.task.strip():
            raise ValueError(f"task: expected a non-empty instruction, got {self.task!r}")
        if self.origin not in ORIGINS:
            raise ValueError(f"origin: expected one of {list(ORIGINS)}, got {self.origin!r}")
        for name in ("subtask_index", "seed"):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, int | np.integer):
                raise ValueError(f"{name}: expected an integer, got {value!r}")
        if not isinstance(self.checkpoint, str):
            raise ValueError(f"checkpoint: expected a string, got {self.checkpoint!r}")
        if self.round_index is not None:
            r = np.asarray(self.round_index)
            if r.shape != (T,) or not np.issubdtype(r.dtype, np.integer) or (r < 0).any():
                raise ValueError(f"round_index: expected {T} non-negative integers, got {r.dtype} {r.shape}")
