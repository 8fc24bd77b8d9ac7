"""One frame as a camera sees it: each camera's model at that frame and what its pixels show.

The head camera is fixed (``RigConfig.head_camera_model``). A wrist camera rides on its gripper: its
model at frame ``i`` is the rig's wrist-camera intrinsics (a pinhole of ``fovy_deg``, square pixels,
centred principal point, as the simulator renders it) at the pose ``T_rig_tcp(state[i]) ·
pose_in_tcp``, from the stored joint state through the rig's forward kinematics. That is rig geometry
and stored state, not simulator state; close to an object a wrist view resolves millimetres the head
view cannot.

Each pixel is an object colour (:func:`pilworld.perception.colour.segment`), the table, or an
*occluder*: grey or dark things that may stand in front of an object (arms, grippers, the fingers in a
wrist view) — and the dark fixture outlines, which lie flat on the table and hide nothing, so
treating them as "no evidence" costs little.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import cv2
import numpy as np
from numpy.typing import NDArray

from calib.camera_model import CameraModel
from pilworld.config.rig import RigConfig
from pilworld.perception.colour import ColourClass, segment
from pilworld.perception.silhouette import BoolArray, View
from pilworld.types import HEAD_VIEW

# "Held": an arm's wrist view shows the object's colour between the fingertips, around the projected tool point.
IN_HAND_PX = 4.0  # radius of the disc around the projected tool point in a wrist view (at 128 px)
IN_HAND_SHARE = 0.4  # share of that disc showing the object's colour when it is held

# Occluders: the arms are grey (HSV saturation ~0), the grippers and outlines dark. The table is a
# light beige (saturation ~0.13–0.14, value ~0.7–0.8 on these renders), so neither test touches it.
OCCLUDER_MAX_SATURATION = 18  # of 255
OCCLUDER_MAX_VALUE = 115  # of 255
MIXED_MIN_SATURATION = 90  # of 255 (0.35, segment's threshold): saturated pixels that match no object


def wrist_camera(rig: RigConfig, view: str, state: NDArray[np.floating]) -> CameraModel:
    """The wrist camera ``view`` at the arm pose of the 14-d ``state``."""
    cam = rig.wrist_cameras[view]
    T_rig_tcp = rig.kinematics.tcp_poses(np.asarray(state, dtype=np.float64))[0 if cam.arm == "left" else 1]
    T_rig_cam = T_rig_tcp @ cam.pose_in_tcp.matrix()
    w, h = rig.image_size.width, rig.image_size.height
    f = h / (2.0 * math.tan(math.radians(cam.fovy_deg) / 2.0))
    K = np.array([[f, 0.0, (w - 1) / 2.0], [0.0, f, (h - 1) / 2.0], [0.0, 0.0, 1.0]])
    return CameraModel(K=K, dist=np.zeros(0), T_cam_base=np.linalg.inv(T_rig_cam), width=w, height=h, name=view)


def frame_cameras(rig: RigConfig, state: NDArray[np.floating], views: Sequence[str]) -> dict[str, CameraModel]:
    """Camera models of ``views`` (head and/or wrist keys of the rig) at one frame's ``state``."""
    out: dict[str, CameraModel] = {}
    for view in views:
        if view == HEAD_VIEW:
            out[view] = rig.head_camera_model
        elif view in rig.wrist_cameras:
            out[view] = wrist_camera(rig, view, state)
    return out


@dataclass(frozen=True)
class Labels:
    """What one image shows: a mask per object colour and the occluder mask (all ``(H, W)`` bool)."""

    masks: Mapping[str, BoolArray]
    occluder: BoolArray


def label_image(image: NDArray[np.uint8], classes: Sequence[ColourClass]) -> Labels:
    """Object-colour masks and the occluder mask of an RGB image."""
    masks = segment(image, classes)
    hsv = cv2.cvtColor(np.ascontiguousarray(image), cv2.COLOR_RGB2HSV)
    occluder = (hsv[..., 1] < OCCLUDER_MAX_SATURATION) | (hsv[..., 2] < OCCLUDER_MAX_VALUE)
    # Strongly coloured but of no object's hue: where two objects meet, the video's 2×2 chroma
    # subsampling mixes their colours (pink + cyan → violet). Such a pixel shows *some* object, so it is
    # no evidence against any of them.
    occluder |= hsv[..., 1] >= MIXED_MIN_SATURATION
    for m in masks.values():
        occluder &= ~m
    return Labels(masks=masks, occluder=occluder)


def object_view(camera: CameraModel, labels: Labels, name: str, hidden_by: Sequence[str]) -> View:
    """The view of object ``name``: its mask, and evidence everywhere but occluders and ``hidden_by`` objects."""
    evidence = ~labels.occluder
    for other in hidden_by:
        evidence = evidence & ~labels.masks[other]
    return View(camera=camera, mask=labels.masks[name], evidence=evidence)
