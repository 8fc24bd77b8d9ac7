"""Where a wrist camera's own gripper covers its image: the planner keeps the board out of that part.

The parallel-jaw gripper of the simulated rig (``simrig.scene``) as boxes (palm and two finger pads),
grown by a few millimetres: a fair stand-in for a real rig's parallel gripper, which is what a wrist
camera beside the palm sees. The mask is kept at 1/:data:`MASK_SCALE` of the image resolution
(docs/calibration.md, "Wrist cameras (eye-in-hand)").
"""

from __future__ import annotations

import math
from typing import Final

import cv2
import numpy as np
import numpy.typing as npt

from calib.camera_model import CameraModel
from simrig.scene import FINGER_CENTRE_BELOW_TCP, FINGER_HALF, PALM_HALF

__all__ = ["MASK_SCALE", "gripper_boxes_tcp", "gripper_mask"]

FloatArray = npt.NDArray[np.float64]

MASK_SCALE: Final = 8  #: the gripper mask is kept at 1/8 of the image resolution
_GRIPPER_INFLATE_M: Final = 0.006  # the gripper boxes are grown by this much


def gripper_boxes_tcp(max_opening_m: float, grip: float) -> list[FloatArray]:
    """``(8, 3)`` corner sets (TCP frame) of the palm and both finger pads at ``grip`` (0 closed … 1 open)."""
    g = min(max(float(grip), 0.0), 1.0)
    e = _GRIPPER_INFLATE_M
    palm_z = -(FINGER_HALF[2] * 2 + PALM_HALF[2]) + FINGER_CENTRE_BELOW_TCP + FINGER_HALF[2]
    signs = np.array([[sx, sy, sz] for sx in (-1, 1) for sy in (-1, 1) for sz in (-1, 1)], dtype=np.float64)
    boxes = [np.array([0.0, 0.0, palm_z]) + signs * (np.array(PALM_HALF) + e)]
    for sign in (1.0, -1.0):
        offset = sign * (g * max_opening_m / 2.0 + FINGER_HALF[1])
        centre = np.array([0.0, offset, FINGER_CENTRE_BELOW_TCP])
        boxes.append(centre + signs * (np.array(FINGER_HALF) + e))
    return boxes


def gripper_mask(camera: CameraModel, boxes: list[FloatArray]) -> npt.NDArray[np.bool_]:
    """Where the gripper covers the image (at 1/MASK_SCALE): each box sampled on a grid, clipped to z > 1 cm.

    ``camera`` is the wrist camera with ``T_cam_base = T_cam_tcp``.
    """
    w, h = math.ceil(camera.width / MASK_SCALE), math.ceil(camera.height / MASK_SCALE)
    mask = np.zeros((h, w), dtype=np.uint8)
    R, t = camera.T_cam_base[:3, :3], camera.T_cam_base[:3, 3]  # T_cam_tcp
    s = np.linspace(0.0, 1.0, 7)
    grid = np.stack(np.meshgrid(s, s, s, indexing="ij"), axis=-1).reshape(-1, 3)
    for box in boxes:
        lo, hi = box.min(axis=0), box.max(axis=0)
        p = (lo + grid * (hi - lo)) @ R.T + t
        p = p[p[:, 2] > 0.01]
        if p.shape[0] < 3:
            continue
        x, y = p[:, 0] / p[:, 2], p[:, 1] / p[:, 2]
        u = (camera.K[0, 0] * x + camera.K[0, 1] * y + camera.K[0, 2] + 0.5) / MASK_SCALE
        v = (camera.K[1, 1] * y + camera.K[1, 2] + 0.5) / MASK_SCALE
        pts = np.clip(np.stack([u, v], axis=1), -1e5, 1e5).astype(np.float32)
        hull = cv2.convexHull(pts).reshape(-1, 2)
        cv2.fillConvexPoly(mask, np.round(hull).astype(np.int32), 1)
    return mask.astype(bool)
