"""Where a gripper let go: an episode's last release as a frame and a head-camera pixel (rig knowledge only).

Whether a pick-and-place subtask succeeded is decided where the object was let go, and that place is
known without knowing the task: the state records when a closed gripper opened, the rig's kinematics
put its tool point in the rig frame at that frame, and the head camera's calibration puts that point in
the image. A full-resolution crop there (:func:`crop`) shows the deciding pixels in a fixed place, which
a network learning from a few hundred episodes cannot find on its own (docs/judges.md, "Learned success
judge": the measured limits).
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np
from numpy.typing import NDArray

from pilworld.config.rig import RigConfig
from pilworld.kinematics.dual_arm import DualArmKinematics

HOLD_MAX = 0.85  # a grip below this is closed, or resting on an object (0 = closed … 1 = open)
OPENING = 0.03  # a rise in grip over one frame this large, from closed: the gripper lets go


@dataclass(frozen=True)
class Release:
    frame: int  # the first frame of the opening
    arm: int  # 0 left, 1 right
    uv: tuple[float, float]  # the tool point in the head image (pixels)
    visible: bool  # in front of the head camera and inside its image


def releases(state: NDArray[np.floating]) -> list[tuple[int, int]]:
    """Every (frame, arm) at which a closed gripper starts to open, in time order (one per opening)."""
    grips = DualArmKinematics.gripper_openings(np.asarray(state, np.float64))  # (T, 2)
    found: list[tuple[int, int]] = []
    for arm in (0, 1):
        opening = (grips[:-1, arm] < HOLD_MAX) & (np.diff(grips[:, arm]) > OPENING)  # frame t → t + 1 opens
        starts = np.flatnonzero(opening & ~np.concatenate([[False], opening[:-1]]))
        found.extend((int(t) + 1, arm) for t in starts)
    return sorted(found)


def last_release(state: NDArray[np.floating], rig: RigConfig) -> Release | None:
    """The episode's last release, or None when no gripper let go."""
    found = releases(state)
    if not found:
        return None
    frame, arm = found[-1]
    tcp = rig.kinematics.gripper_points(np.asarray(state[frame], np.float64))[arm]
    uv, visible = rig.head_camera_model.project(tcp)
    return Release(frame=frame, arm=arm, uv=(float(uv[0]), float(uv[1])), visible=bool(visible))


def crop(image: NDArray[np.uint8], uv: tuple[float, float], size: int) -> NDArray[np.uint8]:
    """A ``size`` × ``size`` crop of ``image`` (H, W, 3) centred on ``uv``; beyond the border, the border repeats."""
    h, w = image.shape[:2]
    half = size // 2
    u = round(min(max(uv[0], 0.0), w - 1.0))
    v = round(min(max(uv[1], 0.0), h - 1.0))
    padded = cv2.copyMakeBorder(image, half, half, half, half, cv2.BORDER_REPLICATE)
    return np.ascontiguousarray(padded[v : v + size, u : u + size])
