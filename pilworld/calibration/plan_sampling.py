"""Candidate views for the pose planner: what the arm moves differs with the camera mount.

* **Eye-to-hand** (:func:`board_candidates`): the arm holds the board in front of the fixed head camera.
  The board centre is uniform in a box of the arm's side of the workspace (``region_*``, y mirrored for
  the right arm); the board normal (out of the printed face) starts pointing at the camera centre and is
  tilted by ``tilt_deg`` about an axis in the board plane (``tilt_axis_deg``: any direction by default);
  the board turns by ``yaw_deg`` about its normal from a nominal in-plane direction in which the holding
  TCP sits on the board's side towards the arm's base.
* **Eye-in-hand** (:func:`camera_candidates`): the arm carries the camera above the board fixed on the
  table. The camera looks at a point within ``aim_offset_m`` of the board centre from ``distance_m`` away,
  along a line tilted ``tilt_deg`` off the board normal towards a random azimuth; the point is seen at
  image row ``aim_v`` (above the gripper, which covers the bottom of a wrist image), and the camera is
  rolled ``roll_deg`` about that line from the orientation closest to its orientation at the start joints
  (so IK stays near them). Varied azimuths and rolls give rotations about many axes, which AX = XB needs.

Both yield :class:`Candidate` views in the rig frame, in the order the random draws are made, for the
shared filters of :mod:`pilworld.calibration.plan_filters` (docs/calibration.md, "3. Hand-eye" and "Wrist
cameras (eye-in-hand)").
"""

from __future__ import annotations

import math
from collections.abc import Iterator
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from calib.board import ChArUcoBoard
from calib.camera_model import CameraModel
from calib.rotations import rigid, rotation_exp
from pilworld.calibration.plan_settings import PlannerSettings, WristPlannerSettings
from pilworld.geometry import invert_transform

__all__ = ["Candidate", "board_candidates", "camera_candidates", "page_points", "unit"]

FloatArray = npt.NDArray[np.float64]


@dataclass(frozen=True, eq=False)
class Candidate:
    """One candidate view: where the board and the camera are, and the TCP pose that puts them there."""

    T_rig_board: FloatArray  #: ``(4, 4)`` board pose (nominal mount)
    T_rig_tcp: FloatArray  #: ``(4, 4)`` TCP pose the arm must reach
    T_rig_held: FloatArray  #: ``(4, 4)`` pose of what the arm moves (board or camera): the spread is measured on it
    camera: CameraModel  #: the camera at its pose for this view
    eye: FloatArray  #: ``(3,)`` camera centre
    page: FloatArray  #: ``(4, 3)`` page corners (with the board's margin)
    corners: FloatArray  #: ``(n, 3)`` chessboard corners
    tilt_deg: float  #: the board normal's (or the optical axis's) angle off the line of sight (board normal)
    yaw_deg: float  #: the board's turn about its normal (or the camera's roll about its optical axis)


def unit(v: FloatArray) -> FloatArray:
    out: FloatArray = v / np.linalg.norm(v, axis=-1, keepdims=True)
    return out


def page_points(board: ChArUcoBoard, nu: int = 2, nv: int = 2) -> FloatArray:
    """``(nu·nv, 3)`` points on the page (board frame, with the margin); 2 x 2: the four page corners in order."""
    m = board.margin_m
    w, h = board.size_m
    if (nu, nv) == (2, 2):
        return np.array([[-m, -m, 0.0], [w + m, -m, 0.0], [w + m, h + m, 0.0], [-m, h + m, 0.0]])
    gu, gv = np.meshgrid(np.linspace(-m, w + m, nu), np.linspace(-m, h + m, nv))
    return np.stack([gu.ravel(), gv.ravel(), np.zeros(gu.size)], axis=1)


def _posed(T: FloatArray, points: FloatArray) -> FloatArray:
    out: FloatArray = points @ T[:3, :3].T + T[:3, 3]
    return out


def board_candidates(
    s: PlannerSettings,
    arm: str,
    camera: CameraModel,
    board: ChArUcoBoard,
    T_tcp_board: FloatArray,
    base_xy: FloatArray,
    rng: np.random.Generator,
) -> Iterator[Candidate]:
    """Eye-to-hand: ``s.candidates`` board poses held by ``arm`` (base at ``base_xy``), sampled at once."""
    n = s.candidates
    sign = 1.0 if arm == "left" else -1.0
    y_lo, y_hi = s.region_y
    y_range = (y_lo, y_hi) if arm == "left" else (-y_hi, -y_lo)
    lo = np.array([s.region_x[0], y_range[0], s.region_z[0]])
    hi = np.array([s.region_x[1], y_range[1], s.region_z[1]])
    centre = lo + (hi - lo) * rng.random((n, 3))
    eye = camera.camera_center_in_base()
    look_from = centre if s.face_camera else np.broadcast_to((lo + hi) / 2.0, (n, 3))
    normal0 = unit(eye - look_from)  # out of the printed face, towards the camera
    # Nominal board x: away from the arm's base, in the board plane, so the TCP (on the board's -x
    # side) is between the board and the base. Fixed per region when not facing the camera.
    away = np.zeros((n, 3))
    away[:, :2] = look_from[:, :2] - base_xy
    away[:, 1] += 1e-9 * sign  # never exactly zero
    x0 = unit(away - np.sum(away * normal0, axis=1, keepdims=True) * normal0)
    z0 = -normal0  # board z points into the board
    y0 = np.cross(z0, x0)
    tilt = np.radians(rng.uniform(*s.tilt_deg, n))
    phi = np.radians(rng.uniform(*s.tilt_axis_deg, n) if s.tilt_axis_deg is not None else rng.uniform(0, 360, n))
    yaw = np.radians(rng.uniform(*s.yaw_deg, n))
    tilt_deg, yaw_deg = np.degrees(np.abs(tilt)), np.degrees(yaw)
    R = np.empty((n, 3, 3))
    for k in range(n):
        R0 = np.stack([x0[k], y0[k], z0[k]], axis=1)
        axis = math.cos(phi[k]) * x0[k] + math.sin(phi[k]) * y0[k]
        # The tilt axis direction is mirrored for the right arm so both arms sample the same motions.
        axis = axis if sign > 0 else np.array([axis[0], -axis[1], axis[2]])
        R[k] = rotation_exp(axis * tilt[k]) @ R0 @ rotation_exp([0.0, 0.0, yaw[k]])
    w, h = board.size_m
    T = np.tile(np.eye(4), (n, 1, 1))
    T[:, :3, :3] = R
    T[:, :3, 3] = centre - R @ np.array([w / 2.0, h / 2.0, 0.0])
    T_board_tcp = invert_transform(T_tcp_board)
    page_b, corners_b = page_points(board), board.corner_points()
    for k in range(n):
        yield Candidate(
            T_rig_board=T[k],
            T_rig_tcp=T[k] @ T_board_tcp,
            T_rig_held=T[k],
            camera=camera,
            eye=eye,
            page=_posed(T[k], page_b),
            corners=_posed(T[k], corners_b),
            tilt_deg=float(tilt_deg[k]),
            yaw_deg=float(yaw_deg[k]),
        )


def _align(a: FloatArray, b: FloatArray) -> FloatArray:
    """The smallest rotation taking unit vector ``a`` to unit vector ``b``."""
    axis = np.cross(a, b)
    s, c = float(np.linalg.norm(axis)), float(np.dot(a, b))
    if s < 1e-12:
        if c > 0:
            return np.eye(3)
        perp = np.cross(a, [1.0, 0.0, 0.0] if abs(a[0]) < 0.9 else [0.0, 1.0, 0.0])
        return rotation_exp(unit(perp) * math.pi)
    return rotation_exp(axis / s * math.atan2(s, c))


def camera_candidates(
    s: WristPlannerSettings,
    camera: CameraModel,
    board: ChArUcoBoard,
    T_rig_board: FloatArray,
    T_rig_tcp_start: FloatArray,
    rng: np.random.Generator,
) -> Iterator[Candidate]:
    """Eye-in-hand: ``s.candidates`` poses of ``camera`` (``T_cam_base = T_cam_tcp``), drawn one by one.

    ``T_rig_tcp_start`` is the TCP at the start joints: the sampled orientations stay close to it.
    """
    T_cam_tcp = np.asarray(camera.T_cam_base, dtype=np.float64)
    w, h = board.size_m
    R_b, t_b = T_rig_board[:3, :3], T_rig_board[:3, 3]
    centre = R_b @ np.array([w / 2.0, h / 2.0, 0.0]) + t_b
    normal = -R_b[:, 2]  # out of the printed face
    x_b, y_b = R_b[:, 0], R_b[:, 1]
    page, corners = _posed(T_rig_board, page_points(board)), _posed(T_rig_board, board.corner_points())
    R_start = (T_rig_tcp_start @ invert_transform(T_cam_tcp))[:3, :3]
    # A horizontal reference for the tilt azimuth: the board normal's plane.
    e1 = unit(np.cross(normal, [0.0, 1.0, 0.0] if abs(normal[1]) < 0.9 else [1.0, 0.0, 0.0]))
    e2 = np.cross(normal, e1)
    # The aimed point is seen at image row aim_v (above the fingers), on the middle column.
    ray_cam = unit(np.linalg.solve(camera.K, [camera.K[0, 2], s.aim_v * camera.height - 0.5, 1.0]))
    to_aim = _align(ray_cam, np.array([0.0, 0.0, 1.0]))
    for _ in range(s.candidates):
        aim = centre + rng.uniform(-1.0, 1.0) * s.aim_offset_m * x_b + rng.uniform(-1.0, 1.0) * s.aim_offset_m * y_b
        tilt = math.radians(rng.uniform(*s.tilt_deg))
        az = math.radians(rng.uniform(*s.azimuth_deg) if s.azimuth_deg is not None else rng.uniform(0.0, 360.0))
        direction = math.cos(tilt) * normal + math.sin(tilt) * (math.cos(az) * e1 + math.sin(az) * e2)
        eye = aim + rng.uniform(*s.distance_m) * direction
        ray = -direction
        roll = math.radians(rng.uniform(*s.roll_deg))
        R = rotation_exp(ray * roll) @ _align(R_start[:, 2], ray) @ R_start @ to_aim
        T_rig_cam = rigid(R, eye)
        yield Candidate(
            T_rig_board=T_rig_board,
            T_rig_tcp=T_rig_cam @ T_cam_tcp,
            T_rig_held=T_rig_cam,
            camera=camera.with_pose(invert_transform(T_rig_cam)),
            eye=eye,
            page=page,
            corners=corners,
            tilt_deg=math.degrees(tilt),
            yaw_deg=math.degrees(roll),
        )
