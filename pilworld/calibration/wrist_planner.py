"""Plan arm poses from which a wrist camera sees a board fixed on the table (eye-in-hand calibration).

For the arm carrying the camera, with the board's (nominal) pose ``T_rig_board`` and the camera's
(nominal) mount ``T_tcp_cam``:

1. **Sample** camera poses: the camera looks at a point within ``aim_offset_m`` of the board centre
   from ``distance_m`` away, along a line tilted ``tilt_deg`` off the board normal towards a random
   azimuth; the point is seen at image row ``aim_v`` (above the gripper, which covers the bottom of a
   wrist image), and the camera is rolled ``roll_deg`` about that line from the orientation closest to
   its orientation at the start joints (so IK stays near them). Varied azimuths and rolls give rotations
   about many axes, which is what AX = XB needs.
2. **Keep** a candidate if IK (nearest to the arm's current joints, within the joint limits) reaches
   the TCP pose, the arm stays above the table, the whole page projects inside the image with a margin
   at most ``max_view_angle_deg`` off its normal, the page stays clear of the camera's own gripper in the
   image (palm and fingers as boxes, :func:`gripper_boxes_tcp`) and no line of sight passes through the
   other arm or this arm's links (capsules, :mod:`.occlusion`).
3. **Choose** ``poses`` of them by farthest-point sampling on camera orientation plus position, ordered
   for short joint moves, and run :func:`calib.handeye_in_hand.check_eye_in_hand_motion` on their TCP poses,
   so motion that cannot determine the mount raises before the robot moves.

The result is a :class:`pilworld.calibration.planner.PosePlan` (``T_rig_board`` is the fixed board in
every pose), so :func:`pilworld.calibration.collect.collect_views` drives any ``Robot`` through it.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Final

import cv2
import numpy as np
import numpy.typing as npt

from calib.board import ChArUcoBoard
from calib.camera_model import CameraModel
from calib.handeye import DegenerateMotionError, check_eye_in_hand_motion
from calib.rotations import rigid, rotation_angle, rotation_exp
from pilworld.calibration.occlusion import arm_capsules, segment_distances
from pilworld.calibration.planner import PlannedPose, PosePlan, visit_order
from pilworld.geometry import invert_transform
from pilworld.kinematics.dual_arm import ArmMount, DualArmKinematics
from pilworld.kinematics.fk import fk_frames
from pilworld.kinematics.ik import ik_nearest
from pilworld.types import ARM_LAYOUT, ARM_SIDES, STATE_DIM
from simrig.scene import FINGER_CENTRE_BELOW_TCP, FINGER_HALF, PALM_HALF

__all__ = ["WristPlannerSettings", "gripper_boxes_tcp", "plan_wrist_poses"]

FloatArray = npt.NDArray[np.float64]

_MIN_LINK_Z: Final = 0.04  # m: joint origins stay this far above the table
_MIN_TCP_Z: Final = 0.10  # m: the fingertips stay clear of the table and the objects on it
_MASK_SCALE: Final = 8  # the gripper mask is kept at 1/8 of the image resolution
_GRIPPER_INFLATE_M: Final = 0.006  # the gripper boxes are grown by this much


def _range(value: tuple[float, float], name: str) -> tuple[float, float]:
    lo, hi = (float(v) for v in value)
    if not (math.isfinite(lo) and math.isfinite(hi) and lo <= hi):
        raise ValueError(f"wrist planner {name}: expected (low, high) with low <= high, got {value!r}")
    return lo, hi


@dataclass(frozen=True)
class WristPlannerSettings:
    """What the wrist-camera pose planner samples and how it filters; metres and degrees, rig frame."""

    poses: int = 20  #: arm poses to choose (at least 3)
    candidates: int = 2500  #: candidate camera poses sampled before filtering
    distance_m: tuple[float, float] = (0.30, 0.46)  #: camera centre to the aimed point
    tilt_deg: tuple[float, float] = (8.0, 35.0)  #: optical axis off the board normal
    roll_deg: tuple[float, float] = (-50.0, 50.0)  #: turn about the optical axis from the nominal orientation
    aim_offset_m: float = 0.03  #: the aimed point lies within this of the board centre (per axis, in its plane)
    #: image row (fraction of the height from the top) where the aimed point appears: above the gripper,
    #: which covers the bottom third of the simulated rig's wrist images
    aim_v: float = 0.33
    #: None: any tilt azimuth; (lo, hi): only these azimuths (degrees about the board normal from rig +x),
    #: e.g. to test degeneracy
    azimuth_deg: tuple[float, float] | None = None
    image_margin: float = 0.04  #: free border around the page, as a fraction of the image size
    max_view_angle_deg: float = 50.0  #: largest angle between a corner's line of sight and the board normal
    clearance_m: float = 0.015  #: extra clearance of the lines of sight from the arm capsules
    position_weight_m: float = 0.2  #: metres of camera distance that count as one radian of rotation
    max_arm_joint_move_rad: float = 2.0  #: largest move of the base, shoulder and elbow from the start joints

    def __post_init__(self) -> None:
        for name in ("poses", "candidates"):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, int) or value < 1:
                raise ValueError(f"wrist planner {name}: expected an integer >= 1, got {value!r}")
        for name in ("distance_m", "tilt_deg", "roll_deg"):
            object.__setattr__(self, name, _range(getattr(self, name), name))
        if self.azimuth_deg is not None:
            object.__setattr__(self, "azimuth_deg", _range(self.azimuth_deg, "azimuth_deg"))
        if not self.distance_m[0] > 0.05:
            raise ValueError(f"wrist planner distance_m: expected metres > 0.05, got {self.distance_m!r}")
        if not 0.0 < self.aim_v < 1.0:
            raise ValueError(f"wrist planner aim_v: expected a fraction in (0, 1), got {self.aim_v!r}")
        if not 0.0 <= self.image_margin < 0.5:
            raise ValueError(f"wrist planner image_margin: expected a fraction in [0, 0.5), got {self.image_margin!r}")
        for name in ("max_view_angle_deg", "position_weight_m", "max_arm_joint_move_rad"):
            if not float(getattr(self, name)) > 0.0:
                raise ValueError(f"wrist planner {name}: expected a positive number, got {getattr(self, name)!r}")
        for name in ("clearance_m", "aim_offset_m"):
            if not float(getattr(self, name)) >= 0.0:
                raise ValueError(f"wrist planner {name}: expected metres >= 0, got {getattr(self, name)!r}")


def gripper_boxes_tcp(max_opening_m: float, grip: float) -> list[FloatArray]:
    """``(8, 3)`` corner sets (TCP frame) of the palm and both finger pads at ``grip`` (0 closed … 1 open).

    The parallel-jaw gripper of the simulated rig (``simrig.scene``), grown by a few millimetres:
    a fair stand-in for a real rig's parallel gripper, which is what a wrist camera beside the palm sees.
    """
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


def _gripper_mask(camera: CameraModel, boxes: list[FloatArray]) -> npt.NDArray[np.bool_]:
    """Where the gripper covers the image (at 1/_MASK_SCALE): each box sampled on a grid, clipped to z > 1 cm."""
    w, h = math.ceil(camera.width / _MASK_SCALE), math.ceil(camera.height / _MASK_SCALE)
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
        u = (camera.K[0, 0] * x + camera.K[0, 1] * y + camera.K[0, 2] + 0.5) / _MASK_SCALE
        v = (camera.K[1, 1] * y + camera.K[1, 2] + 0.5) / _MASK_SCALE
        pts = np.clip(np.stack([u, v], axis=1), -1e5, 1e5).astype(np.float32)
        hull = cv2.convexHull(pts).reshape(-1, 2)
        cv2.fillConvexPoly(mask, np.round(hull).astype(np.int32), 1)
    return mask.astype(bool)


def _mount(kinematics: DualArmKinematics, arm: str) -> ArmMount:
    if arm not in ARM_SIDES:
        raise ValueError(f"arm: expected one of {', '.join(ARM_SIDES)}, got {arm!r}")
    mount: ArmMount = getattr(kinematics, arm)
    return mount


def _unit(v: FloatArray) -> FloatArray:
    out: FloatArray = v / np.linalg.norm(v, axis=-1, keepdims=True)
    return out


def _align(a: FloatArray, b: FloatArray) -> FloatArray:
    """The smallest rotation taking unit vector ``a`` to unit vector ``b``."""
    axis = np.cross(a, b)
    s, c = float(np.linalg.norm(axis)), float(np.dot(a, b))
    if s < 1e-12:
        if c > 0:
            return np.eye(3)
        perp = np.cross(a, [1.0, 0.0, 0.0] if abs(a[0]) < 0.9 else [0.0, 1.0, 0.0])
        return rotation_exp(_unit(perp) * math.pi)
    return rotation_exp(axis / s * math.atan2(s, c))


def plan_wrist_poses(
    kinematics: DualArmKinematics,
    camera: CameraModel,
    board: ChArUcoBoard,
    T_rig_board: npt.ArrayLike,
    arm: str,
    current_state: npt.ArrayLike,
    settings: WristPlannerSettings | None = None,
    seed: int = 0,
    *,
    max_opening_m: float = 0.085,
    for_calibration: bool = True,
) -> PosePlan:
    """Choose ``settings.poses`` reachable, unoccluded, diverse views of the table board (module docstring).

    ``camera`` is the wrist camera with ``T_cam_base = T_cam_tcp`` (as :meth:`RigConfig.wrist_camera_model`
    returns it; any resolution: only its field of view and mount matter, and they may be nominal);
    ``T_rig_board`` the board's (nominal) pose; ``current_state`` ``(14,)`` the robot's state (IK seeds
    from this arm's joints; the other arm holds still there; the grip and ``max_opening_m``, the gripper's
    stroke, set where the fingers cover the image). Raises
    :class:`calib.handeye.DegenerateMotionError` if the chosen poses cannot determine the mount,
    ``ValueError`` for bad settings or when no candidate is feasible.
    """
    s = settings or WristPlannerSettings()
    mount = _mount(kinematics, arm)
    other = "right" if arm == "left" else "left"
    state = np.asarray(current_state, dtype=np.float64).reshape(STATE_DIM)
    arm_idx, grip_idx = ARM_LAYOUT[arm]
    q_start = state[arm_idx]
    T_board = np.asarray(T_rig_board, dtype=np.float64)
    T_cam_tcp = np.asarray(camera.T_cam_base, dtype=np.float64)
    T_tcp_cam = invert_transform(T_cam_tcp)
    rng = np.random.default_rng([seed, 0 if arm == "left" else 1, 2024])
    T_base_rig = invert_transform(mount.T_rig_base)
    others = arm_capsules(getattr(kinematics, other), state[ARM_LAYOUT[other][0]])
    blocked = _gripper_mask(camera, gripper_boxes_tcp(max_opening_m, float(state[grip_idx])))
    blocked = cv2.dilate(blocked.astype(np.uint8), np.ones((3, 3), np.uint8)).astype(bool)

    corners_b = board.corner_points()
    m = board.margin_m
    w, h = board.size_m
    page_b = np.array([[-m, -m, 0.0], [w + m, -m, 0.0], [w + m, h + m, 0.0], [-m, h + m, 0.0]])
    gu, gv = np.meshgrid(np.linspace(-m, w + m, 15), np.linspace(-m, h + m, 11))
    page_grid_b = np.stack([gu.ravel(), gv.ravel(), np.zeros(gu.size)], axis=1)
    R_b, t_b = T_board[:3, :3], T_board[:3, 3]
    centre = R_b @ np.array([w / 2.0, h / 2.0, 0.0]) + t_b
    normal = -R_b[:, 2]  # out of the printed face
    x_b, y_b = R_b[:, 0], R_b[:, 1]
    page = page_b @ R_b.T + t_b
    page_grid = page_grid_b @ R_b.T + t_b
    corners = corners_b @ R_b.T + t_b
    T_rig_cam_start = mount.tcp_pose(q_start) @ T_tcp_cam
    R_start = T_rig_cam_start[:3, :3]
    margin_u, margin_v = s.image_margin * camera.width, s.image_margin * camera.height
    cos_view = math.cos(math.radians(s.max_view_angle_deg))
    # A horizontal reference for the tilt azimuth: the board normal's plane.
    e1 = _unit(np.cross(normal, [0.0, 1.0, 0.0] if abs(normal[1]) < 0.9 else [1.0, 0.0, 0.0]))
    e2 = np.cross(normal, e1)
    # The aimed point is seen at image row aim_v (above the fingers), on the middle column.
    ray_cam = _unit(np.linalg.solve(camera.K, [camera.K[0, 2], s.aim_v * camera.height - 0.5, 1.0]))
    to_aim = _align(ray_cam, np.array([0.0, 0.0, 1.0]))
    rejected: dict[str, int] = {}
    feasible: list[PlannedPose] = []
    cams: list[FloatArray] = []

    def reject(reason: str) -> None:
        rejected[reason] = rejected.get(reason, 0) + 1

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
        cam = camera.with_pose(invert_transform(T_rig_cam))
        proj = cam.project_detailed(page)
        uv = proj.uv
        inside = (
            proj.in_valid_fov.all()
            and uv[:, 0].min() >= margin_u - 0.5
            and uv[:, 0].max() <= camera.width - 0.5 - margin_u
            and uv[:, 1].min() >= margin_v - 0.5
            and uv[:, 1].max() <= camera.height - 0.5 - margin_v
        )
        if not inside:
            reject("not inside the image")
            continue
        if np.min(_unit(eye - corners) @ normal) < cos_view:
            reject("too oblique")
            continue
        grid_uv = cam.project(page_grid)[0]
        iu = np.clip(((grid_uv[:, 0] + 0.5) / _MASK_SCALE).astype(int), 0, blocked.shape[1] - 1)
        iv = np.clip(((grid_uv[:, 1] + 0.5) / _MASK_SCALE).astype(int), 0, blocked.shape[0] - 1)
        if blocked[iv, iu].any():
            reject("page behind the gripper in the image")
            continue
        T_rig_tcp = T_rig_cam @ T_cam_tcp
        q = ik_nearest(T_base_rig @ T_rig_tcp, mount.dh, q_start, mount.T_flange_tcp)
        if q is None:
            reject("unreachable")
            continue
        if np.max(np.abs(q[:3] - q_start[:3])) > s.max_arm_joint_move_rad:
            reject("far from the start joints")
            continue
        frames = mount.T_rig_base @ fk_frames(q, mount.dh)
        if frames[1:, 2, 3].min() < _MIN_LINK_Z or T_rig_tcp[2, 3] < _MIN_TCP_Z or eye[2] < _MIN_TCP_Z:
            reject("arm too low")
            continue
        own = arm_capsules(mount, q).links()
        # Capsules the camera sits in (the wrist links beside it) are behind it: the gripper mask covers the rest.
        near = segment_distances(eye[None], eye[None], own.start, own.end)[0] < own.radius + s.clearance_m
        both = others + type(own)(own.start[~near], own.end[~near], own.radius[~near], own.gripper[~near])
        lines = np.concatenate([corners, page])
        dist = segment_distances(np.broadcast_to(eye, lines.shape), lines, both.start, both.end)
        if np.any(dist < both.radius + s.clearance_m):
            reject("line of sight blocked by an arm")
            continue
        feasible.append(PlannedPose(q, T_rig_tcp, T_board, math.degrees(tilt), math.degrees(roll)))
        cams.append(T_rig_cam)
    if not feasible:
        reasons = ", ".join(f"{r}: {c}" for r, c in sorted(rejected.items(), key=lambda x: -x[1]))
        raise ValueError(
            f"wrist pose planner ({arm} arm): none of {s.candidates} candidate camera poses is feasible ({reasons})"
        )
    chosen = _farthest_points(np.asarray(cams), s.poses, s.position_weight_m)
    ordered = visit_order([feasible[i] for i in chosen], q_start)
    motion = None
    if for_calibration:
        try:
            motion = check_eye_in_hand_motion([p.T_rig_tcp for p in ordered])
        except DegenerateMotionError as exc:
            raise DegenerateMotionError(f"{arm} arm, planned wrist-camera poses: {exc}") from None
    return PosePlan(
        arm=arm, poses=tuple(ordered), motion=motion, feasible=len(feasible), sampled=s.candidates, rejected=rejected
    )


def _distances(cams: FloatArray, k: int, position_weight_m: float) -> FloatArray:
    R_k, c_k = cams[k, :3, :3], cams[k, :3, 3]
    out = np.empty(cams.shape[0])
    for i in range(cams.shape[0]):
        out[i] = (
            rotation_angle(cams[i, :3, :3] @ R_k.T) + float(np.linalg.norm(cams[i, :3, 3] - c_k)) / position_weight_m
        )
    return out


def _farthest_points(cams: FloatArray, n: int, position_weight_m: float) -> list[int]:
    n = min(n, cams.shape[0])
    first = int(np.argmax(_distances(cams, 0, position_weight_m)))
    chosen = [first]
    nearest = _distances(cams, first, position_weight_m)
    while len(chosen) < n:
        k = int(np.argmax(nearest))
        chosen.append(k)
        nearest = np.minimum(nearest, _distances(cams, k, position_weight_m))
    return chosen
