"""Drawing tracked objects into predicted frames, and erasing where they no longer are.

An object that moves (held, or let go, in the chunk) is drawn at its pose in every view: a box as its
visible faces, a bowl as its silhouette with its darker opening, each face lit by a fixed light from
above (the simulator's look closely enough for colour-based perception: only the hue classifies an
object, :mod:`pilworld.perception.colour`). The robot render's depth occludes it where the robot is
nearer. Its colour anywhere else in that view (where it was, a ghost the blend left) is replaced by
the empty scene: the head camera's plate, or a wrist view's table colour.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import cv2
import numpy as np
from numpy.typing import NDArray

from calib.camera_model import CameraModel
from pilworld.config.rig import RigConfig
from pilworld.perception.colour import ColourClass, segment
from pilworld.perception.silhouette import BoxShape, Pose2D, Shape, silhouette_uv
from pilworld.perception.views import wrist_camera
from pilworld.types import HEAD_VIEW

LIGHT = np.array([0.3, 0.2, 1.0]) / np.linalg.norm([0.3, 0.2, 1.0])
AMBIENT = 0.62
_SHIFT = 4
U8 = NDArray[np.uint8]
F64 = NDArray[np.float64]


def _shade(normal: F64) -> float:
    return AMBIENT + (1.0 - AMBIENT) * max(0.0, float(normal @ LIGHT))


# A box's corners are the 8 sign combinations (x, y, z) ∈ {−1, 1}³ of its half-edge; each face lists four of
# them in order round the face, with its outward normal (in the box's frame).
_SIGNS = np.array([(x, y, z) for x in (-1, 1) for y in (-1, 1) for z in (-1, 1)], dtype=np.float64)
_FACES = (
    ((0, 1, 3, 2), (-1.0, 0.0, 0.0)),
    ((4, 6, 7, 5), (1.0, 0.0, 0.0)),
    ((0, 4, 5, 1), (0.0, -1.0, 0.0)),
    ((2, 3, 7, 6), (0.0, 1.0, 0.0)),
    ((0, 2, 6, 4), (0.0, 0.0, -1.0)),
    ((1, 5, 7, 3), (0.0, 0.0, 1.0)),
)


def _box_corners(edge: float, pose: Pose2D) -> tuple[F64, F64]:
    """A box's 8 rig-frame corners and its rotation."""
    h = edge / 2
    c, s = math.cos(pose.yaw), math.sin(pose.yaw)
    R = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
    return (_SIGNS * h) @ R.T + np.array([pose.x, pose.y, pose.z + h]), R


def _ring(radius: float, z: float, pose: Pose2D, n: int = 24) -> F64:
    phi = np.linspace(0.0, 2.0 * math.pi, n, endpoint=False)
    return np.column_stack([pose.x + radius * np.cos(phi), pose.y + radius * np.sin(phi), np.full(n, z)])


def _polygons(camera: CameraModel, shape: Shape, pose: Pose2D, colour: F64) -> list[tuple[float, F64, F64]]:
    """(camera depth, pixel polygon, RGB) of each visible part of one object."""
    out: list[tuple[float, F64, F64]] = []
    if isinstance(shape, BoxShape):
        corners, R = _box_corners(shape.edge, pose)
        depth = camera.points_to_camera(corners)[:, 2]
        if not np.all(depth > 1e-3):
            return out
        uv, _ = camera.project(corners)
        T = camera.T_cam_base
        eye = -T[:3, :3].T @ T[:3, 3]  # the camera centre in the rig frame
        for quad, normal in _FACES:
            n = R @ np.asarray(normal)
            idx = list(quad)
            if float(n @ (eye - corners[idx].mean(axis=0))) <= 0:
                continue  # facing away
            out.append((float(depth[idx].mean()), uv[idx], colour * _shade(n)))
        return out
    hull = silhouette_uv(camera, shape, pose)
    if hull is None:
        return out
    centre = np.array([[pose.x, pose.y, pose.z + shape.height / 2]])
    d = float(camera.points_to_camera(centre)[0, 2])
    out.append((d, hull, colour * 0.95))
    rim = _ring(shape.top_radius - shape.wall / 2, pose.z + shape.height, pose)
    if np.all(camera.points_to_camera(rim)[:, 2] > 1e-3):
        uv, _ = camera.project(rim)
        out.append((d - 1e-4, cv2.convexHull(uv.astype(np.float32)).reshape(-1, 2).astype(np.float64), colour * 0.72))
    return out


def draw_objects(
    image: U8,
    camera: CameraModel,
    objects: Sequence[tuple[Shape, Pose2D, F64]],
    robot_depth: NDArray[np.float32],
) -> tuple[U8, dict[int, NDArray[np.bool_]]]:
    """``image`` with ``objects`` (shape, pose, RGB) drawn, nearer than the robot; and each one's drawn pixels."""
    h, w = image.shape[:2]
    out = image.copy()
    zbuf = np.where(robot_depth > 0, robot_depth, np.inf).astype(np.float64)
    parts = []
    for index, (shape, pose, colour) in enumerate(objects):
        for depth, uv, rgb in _polygons(camera, shape, pose, colour):
            parts.append((depth, index, uv, rgb))
    masks = {i: np.zeros((h, w), bool) for i in range(len(objects))}
    for depth, index, uv, rgb in sorted(parts, key=lambda p: -p[0]):  # far to near
        if not np.all(np.isfinite(uv)) or np.abs(uv).max() > 8 * max(h, w):
            continue
        # Rasterised in the polygon's bounding window only (a face covers a few dozen of 16k pixels); the
        # window moves by whole pixels, so the fill is the full frame's.
        pts = np.round(uv * (1 << _SHIFT)).astype(np.int32)
        lo, hi = pts.min(axis=0) >> _SHIFT, pts.max(axis=0) >> _SHIFT
        x0, y0 = max(0, int(lo[0])), max(0, int(lo[1]))
        x1, y1 = min(w, int(hi[0]) + 2), min(h, int(hi[1]) + 2)
        if x1 <= x0 or y1 <= y0:
            continue
        canvas = np.zeros((y1 - y0, x1 - x0), np.uint8)
        offset = np.array([x0 << _SHIFT, y0 << _SHIFT], np.int32)
        cv2.fillConvexPoly(canvas, pts - offset, 1, lineType=cv2.LINE_8, shift=_SHIFT)
        win = (slice(y0, y1), slice(x0, x1))
        px = (canvas > 0) & (depth < zbuf[win])
        if not px.any():
            continue
        out[win][px] = np.clip(rgb, 0, 255).astype(np.uint8)
        zbuf[win][px] = depth
        for m in masks.values():
            m[win][px] = False
        masks[index][win] |= px
    return out, masks


def erase_elsewhere(
    image: U8,
    colours: Sequence[ColourClass],
    keep: Sequence[NDArray[np.bool_]],
    robot: NDArray[np.bool_],
    background: U8,
) -> U8:
    """``image`` with each colour's pixels outside its ``keep`` mask (and off the robot) replaced by ``background``."""
    if not colours:
        return image
    found = segment(image, list(colours))
    mask = np.zeros(image.shape[:2], bool)
    for colour, kept in zip(colours, keep, strict=True):
        mask |= found[colour.name] & ~kept
    mask &= ~robot
    if not mask.any():
        return image
    grown = cv2.dilate(mask.astype(np.uint8), np.ones((3, 3), np.uint8)) > 0
    grown &= ~robot
    for kept in keep:
        grown &= ~kept
    out = image.copy()
    out[grown] = background[grown]
    return out


def view_cameras(rig: RigConfig, view: str, poses: NDArray[np.floating]) -> list[CameraModel] | None:
    """The camera model of ``view`` at each of the (K, 14) ``poses`` (a wrist camera moves with its arm);
    None for a view the rig does not have."""
    if view == HEAD_VIEW:
        return [rig.head_camera_model] * len(poses)
    if view not in rig.wrist_cameras:
        return None
    first = wrist_camera(rig, view, poses[0])
    cam = rig.wrist_cameras[view]
    side = 0 if cam.arm == "left" else 1
    T_rig_cam = rig.kinematics.tcp_poses(np.asarray(poses, np.float64))[:, side] @ cam.pose_in_tcp.matrix()
    out = [first]
    for T in T_rig_cam[1:]:
        out.append(
            CameraModel(
                K=first.K,
                dist=first.dist,
                T_cam_base=np.linalg.inv(T),
                width=first.width,
                height=first.height,
                name=view,
            )
        )
    return out
