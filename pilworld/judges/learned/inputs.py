"""What the learned success judge sees of an episode, and the check that an episode is one it can judge.

A person judging success looks at how the episode ends and compares it with how it began, knowing the
instruction. The judge sees the same and nothing else (docs/judges.md, "The learned success judge"):

* **frames**: for every view, the first frame and one of the last frames, resized to ``side`` × ``side``
  and stacked on the channels (6 channels per view): what changed is as visible as where things are;
* **state**: the robot state (joints, grippers) at the first and at that last frame;
* **context**: the instruction, as hashed words and word pairs (any text, no vocabulary to download), and
  the subtask index, one-hot.

No task file, no object list, no simulator state: a real rig records all of it. ``end`` picks which of
the last frames: training draws it at random among the last :data:`END_FRAMES`, judging averages over
them (the scene at rest does not change there, the arm may still move away).
"""

from __future__ import annotations

import itertools
import re
import zlib
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

import cv2
import numpy as np
from numpy.typing import NDArray

from pilworld.types import HEAD_VIEW

SIDE = 64  # frames are resized to SIDE × SIDE (the rig's 128² cameras, halved)
END_FRAMES = 3  # the last frames a verdict looks at (training draws one, judging averages all)
TEXT_BUCKETS = 64  # hashed words and word pairs of the instruction
MAX_SUBTASKS = 16  # subtask indices one-hot; higher ones share the last slot
CONTEXT_DIM = TEXT_BUCKETS + MAX_SUBTASKS


class JudgeInputError(ValueError):
    """An episode the judge cannot read: other views, image sizes or state than it was trained on."""


@dataclass(frozen=True)
class InputSpec:
    """The cameras and state a judge was trained on; every episode it judges must match them."""

    views: tuple[str, ...]  # in the order the network reads them
    image_sizes: tuple[tuple[int, int], ...]  # (height, width) per view, as recorded
    state_dim: int
    side: int = SIDE
    release_crop: int = 0  # > 0: also a crop of this many head pixels where a gripper last let go (needs the rig)

    @property
    def inputs(self) -> int:
        """Image inputs the network reads: the views, and the release crop when there is one."""
        return len(self.views) + (1 if self.release_crop else 0)

    def __post_init__(self) -> None:
        if not self.views:
            raise ValueError("views: a judge needs at least one camera view")
        if len(self.image_sizes) != len(self.views):
            raise ValueError(f"image_sizes: expected one (height, width) per view, got {len(self.image_sizes)}")
        if self.state_dim < 1 or self.side < 16:
            raise ValueError(f"state_dim {self.state_dim} / side {self.side}: expected ≥ 1 / ≥ 16")
        if self.release_crop and not 8 <= self.release_crop <= 256:
            raise ValueError(f"release_crop: expected 0 or 8..256 pixels, got {self.release_crop}")
        if self.release_crop and HEAD_VIEW not in self.views:
            raise ValueError(
                f"release_crop: the crop is cut from the head view {HEAD_VIEW!r}, not among {list(self.views)}"
            )

    @classmethod
    def from_views(
        cls, views: Mapping[str, tuple[int, int]], state_dim: int, side: int = SIDE, release_crop: int = 0
    ) -> InputSpec:
        names = tuple(sorted(views))
        sizes = tuple((int(views[v][0]), int(views[v][1])) for v in names)
        return cls(views=names, image_sizes=sizes, state_dim=state_dim, side=side, release_crop=release_crop)

    def to_json(self) -> dict[str, Any]:
        return {
            "views": {v: list(s) for v, s in zip(self.views, self.image_sizes, strict=True)},
            "state_dim": self.state_dim,
            "side": self.side,
            "release_crop": self.release_crop,
        }

    @classmethod
    def from_json(cls, data: Mapping[str, Any]) -> InputSpec:
        views = data["views"]
        if not isinstance(views, Mapping):
            raise ValueError(f"views: expected a mapping of view → [height, width], got {views!r}")
        sizes = {str(v): (int(s[0]), int(s[1])) for v, s in views.items()}
        return cls.from_views(sizes, int(data["state_dim"]), int(data["side"]), int(data.get("release_crop", 0)))

    def check(self, views: Mapping[str, tuple[int, ...]], state_dim: int, what: str) -> None:
        """Raise :class:`JudgeInputError` naming what differs between ``what`` and the judge's training data."""
        mine = dict(zip(self.views, self.image_sizes, strict=True))
        theirs = {v: tuple(int(x) for x in s[:2]) for v, s in views.items()}
        if set(theirs) != set(mine):
            raise JudgeInputError(
                f"{what} has cameras {sorted(theirs)}, the judge was trained on {sorted(mine)} "
                "(a judge trained on another rig's cameras: train one on this rig's episodes)"
            )
        for v in self.views:
            if theirs[v] != mine[v]:
                raise JudgeInputError(
                    f"{what}: camera {v!r} records {theirs[v][0]}×{theirs[v][1]} images, "
                    f"the judge was trained on {mine[v][0]}×{mine[v][1]}"
                )
        if state_dim != self.state_dim:
            raise JudgeInputError(f"{what} has a {state_dim}-value state, the judge was trained on {self.state_dim}")


def resize(frame: NDArray[np.uint8], side: int) -> NDArray[np.uint8]:
    """One RGB frame (H, W, 3) at ``side`` × ``side`` (area averaging: no aliasing of thin edges)."""
    if frame.shape[0] == side and frame.shape[1] == side:
        return np.ascontiguousarray(frame)
    return np.asarray(cv2.resize(frame, (side, side), interpolation=cv2.INTER_AREA), np.uint8)


def view_stack(first: NDArray[np.uint8], last: NDArray[np.uint8], side: int) -> NDArray[np.uint8]:
    """(6, side, side) uint8: the first frame's channels, then the last frame's."""
    return np.concatenate([resize(first, side), resize(last, side)], axis=2).transpose(2, 0, 1).copy()


_WORD = re.compile(r"[a-z0-9]+")


def context_vector(instruction: str, subtask: int) -> NDArray[np.float32]:
    """Hashed words and word pairs of ``instruction`` (L2-normalised) and the subtask index, one-hot."""
    words = _WORD.findall(instruction.lower())
    tokens = words + [f"{a} {b}" for a, b in itertools.pairwise(words)]
    out = np.zeros(CONTEXT_DIM, dtype=np.float32)
    for t in tokens:
        out[zlib.crc32(t.encode()) % TEXT_BUCKETS] += 1.0
    norm = float(np.linalg.norm(out[:TEXT_BUCKETS]))
    if norm > 0:
        out[:TEXT_BUCKETS] /= norm
    out[TEXT_BUCKETS + min(max(int(subtask), 0), MAX_SUBTASKS - 1)] = 1.0
    return out


def instruction_key(instruction: str) -> str:
    """The instruction as the judge compares it with those it was trained on (case and spacing ignored)."""
    return " ".join(_WORD.findall(instruction.lower()))
