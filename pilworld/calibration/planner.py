"""Plan reachable, diverse board poses for eye-to-hand calibration of the head camera.

For one arm holding the board at a (nominal) ``T_tcp_board``:

1. **Sample** candidate board poses: the board centre uniformly in a box of the arm's side of the
   workspace (``region_*``, y mirrored for the right arm); the board normal (out of the printed face)
   starts pointing at the camera centre and is tilted by ``tilt_deg`` about an axis in the board plane
   (``tilt_axis_deg``: any direction by default); the board turns by ``yaw_deg`` about its normal from
   a nominal in-plane direction in which the holding TCP sits on the board's side towards the arm's base.
2. **Keep** a candidate if IK (nearest to the arm's current joints, within the joint limits) reaches
   the TCP pose it needs, the arm stays above the table, the whole page projects inside the image with a
   margin, every chessboard corner is seen at most ``max_view_angle_deg`` off its normal, no line of
   sight to the board passes through either arm (capsule model, :mod:`.occlusion`), and the plate does
   not cut through the holding arm.
3. **Choose** ``poses`` of them greedily by farthest-point sampling on orientation (geodesic angle) plus
   position (``position_weight_m`` metres count as one radian): each new pose is the candidate farthest
   from those chosen, which spreads rotation angles *and* axes, then order them for short joint moves.

:func:`plan_board_poses` then runs :func:`calib.handeye.check_motion` on the chosen TCP poses, so
settings that cannot determine the hand-eye transform (tilts of a few degrees, a single tilt axis, fewer
than 3 poses) raise :class:`calib.handeye.DegenerateMotionError` naming the cause before the robot moves.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Final

import numpy as np
import numpy.typing as npt

from calib.board import ChArUcoBoard
from calib.camera_model import CameraModel
from calib.handeye import DegenerateMotionError, MotionReport, check_motion
from calib.rotations import rotation_angle, rotation_exp
from pilworld.calibration.occlusion import arm_capsules, segment_distances
from pilworld.geometry import invert_transform
from pilworld.kinematics.dual_arm import ArmMount, DualArmKinematics
from pilworld.kinematics.fk import fk_frames
from pilworld.kinematics.ik import ik_nearest
from pilworld.types import ARM_LAYOUT, ARM_SIDES, STATE_DIM

__all__ = ["PlannedPose", "PlannerSettings", "PosePlan", "plan_board_poses"]

FloatArray = npt.NDArray[np.float64]

_MIN_LINK_Z: Final = 0.04  # m: joint origins stay this far above the table
_MIN_TCP_Z: Final = 0.10  # m: the gripper stays clear of the objects on the table
_MIN_BOARD_Z: Final = 0.03  # m: the plate stays above the table


def _range(value: tuple[float, float], name: str) -> tuple[float, float]:
    lo, hi = (float(v) for v in value)
    if not (math.isfinite(lo) and math.isfinite(hi) and lo <= hi):
        raise ValueError(f"planner {name}: expected (low, high) with low <= high, got {value!r}")
    return lo, hi


@dataclass(frozen=True)
class PlannerSettings:
    """What the pose planner samples and how it filters; metres and degrees, rig frame."""

    poses: int = 20  #: board poses to choose (at least 3)
    candidates: int = 2000  #: candidate poses sampled before filtering
    region_x: tuple[float, float] = (-0.25, 0.25)  #: board-centre x range
    #: board-centre y range for the left arm (the right arm uses the mirror image, -high..-low)
    region_y: tuple[float, float] = (-0.08, 0.30)
    region_z: tuple[float, float] = (0.12, 0.45)  #: board-centre height above the table
    #: tilt of the board normal off the line of sight to the camera (a negative tilt leans the other way)
    tilt_deg: tuple[float, float] = (15.0, 35.0)
    #: direction of the tilt axis in the board plane (0 = the board's nominal x axis); None: any direction
    tilt_axis_deg: tuple[float, float] | None = None
    yaw_deg: tuple[float, float] = (-45.0, 45.0)  #: turn about the normal from the nominal in-plane direction
    #: start from a normal pointing at the camera from each sampled centre (True) or from the region's
    #: centre for every pose (False: then tilt and yaw alone set the orientation, e.g. to test degeneracy)
    face_camera: bool = True
    image_margin: float = 0.03  #: free border around the page, as a fraction of the image size
    max_view_angle_deg: float = 50.0  #: largest angle between a corner's line of sight and the board normal
    clearance_m: float = 0.015  #: extra clearance of lines of sight and of the plate from the arm capsules
    position_weight_m: float = 0.2  #: metres of board-centre distance that count as one radian of rotation
    max_arm_joint_move_rad: float = 2.0  #: largest move of the base, shoulder and elbow from the start joints

    def __post_init__(self) -> None:
        if isinstance(self.poses, bool) or not isinstance(self.poses, int) or self.poses < 1:
            raise ValueError(f"planner poses: expected an integer >= 1, got {self.poses!r}")
        if isinstance(self.candidates, bool) or not isinstance(self.candidates, int) or self.candidates < 1:
            raise ValueError(f"planner candidates: expected an integer >= 1, got {self.candidates!r}")
        for name in ("region_x", "region_y", "region_z", "tilt_deg", "yaw_deg"):
            object.__setattr__(self, name, _range(getattr(self, name), name))
        if self.tilt_axis_deg is not None:
            object.__setattr__(self, "tilt_axis_deg", _range(self.tilt_axis_deg, "tilt_axis_deg"))
        if not 0.0 <= self.image_margin < 0.5:
            raise ValueError(f"planner image_margin: expected a fraction in [0, 0.5), got {self.image_margin!r}")
        for name in ("max_view_angle_deg", "position_weight_m", "max_arm_joint_move_rad"):
            if not float(getattr(self, name)) > 0.0:
                raise ValueError(f"planner {name}: expected a positive number, got {getattr(self, name)!r}")
        if not self.clearance_m >= 0.0:
            raise ValueError(f"planner clearance_m: expected metres >= 0, got {self.clearance_m!r}")


@dataclass(frozen=True, eq=False)
class PlannedPose:
    """One chosen board pose and the joints that reach it."""

    q: FloatArray  #: ``(6,)`` joint angles of the holding arm (radians)
    T_rig_tcp: FloatArray  #: ``(4, 4)`` TCP pose (rig frame) the joints reach
    T_rig_board: FloatArray  #: ``(4, 4)`` nominal board pose (rig frame) with the nominal ``T_tcp_board``
    tilt_deg: float  #: angle between the board normal and the line of sight to the camera
    yaw_deg: float  #: turn about the normal from the nominal in-plane direction


@dataclass(frozen=True, eq=False)
class PosePlan:
    """The chosen poses for one arm, in the order to visit them."""

    arm: str
    poses: tuple[PlannedPose, ...]
    motion: MotionReport | None  #: rotation span and axis spread of the chosen TCP poses (None: not checked)
    feasible: int  #: candidates that passed every check
    sampled: int  #: candidates sampled
    rejected: dict[str, int] = field(default_factory=dict)  #: rejections by reason

    def states(self, hold: npt.ArrayLike) -> FloatArray:
        """``(N, 14)`` commands: the other arm and both grips as in ``hold`` ``(14,)``, this arm at each pose."""
        base = np.asarray(hold, dtype=np.float64).reshape(STATE_DIM)
        out = np.repeat(base[None], len(self.poses), axis=0)
        out[:, ARM_LAYOUT[self.arm][0]] = [p.q for p in self.poses]
        return out

    def summary(self) -> str:
        text = f"{self.arm} arm: {len(self.poses)} board poses chosen from {self.feasible} feasible"
        text += f" of {self.sampled} sampled"
        if self.motion is not None:
            text += f"; rotation span {self.motion.rotation_span_deg:.1f}°, axis spread {self.motion.axis_spread:.2f}"
        return text


def _unit(v: FloatArray) -> FloatArray:
    out: FloatArray = v / np.linalg.norm(v, axis=-1, keepdims=True)
    return out


def _mount(kinematics: DualArmKinematics, arm: str) -> ArmMount:
    if arm not in ARM_SIDES:
        raise ValueError(f"arm: expected one of {', '.join(ARM_SIDES)}, got {arm!r}")
    mount: ArmMount = getattr(kinematics, arm)
    return mount


class _Candidates:
    """Vectorised sampling of board poses (rig frame)."""

    def __init__(
        self,
        settings: PlannerSettings,
        arm: str,
        camera: CameraModel,
        board: ChArUcoBoard,
        base_xy: FloatArray,
        rng: np.random.Generator,
    ) -> None:
        s, n = settings, settings.candidates
        sign = 1.0 if arm == "left" else -1.0
        y_lo, y_hi = s.region_y
        y_range = (y_lo, y_hi) if arm == "left" else (-y_hi, -y_lo)
        lo = np.array([s.region_x[0], y_range[0], s.region_z[0]])
        hi = np.array([s.region_x[1], y_range[1], s.region_z[1]])
        self.centre = lo + (hi - lo) * rng.random((n, 3))
        eye = camera.camera_center_in_base()
        look_from = self.centre if s.face_camera else np.broadcast_to((lo + hi) / 2.0, (n, 3))
        normal0 = _unit(eye - look_from)  # out of the printed face, towards the camera
        # Nominal board x: away from the arm's base, in the board plane, so the TCP (on the board's -x
        # side) is between the board and the base. Fixed per region when not facing the camera.
        away = np.zeros((n, 3))
        away[:, :2] = look_from[:, :2] - base_xy
        away[:, 1] += 1e-9 * sign  # never exactly zero
        x0 = _unit(away - np.sum(away * normal0, axis=1, keepdims=True) * normal0)
        z0 = -normal0  # board z points into the board
        y0 = np.cross(z0, x0)
        tilt = np.radians(rng.uniform(*s.tilt_deg, n))
        phi = np.radians(rng.uniform(*s.tilt_axis_deg, n) if s.tilt_axis_deg is not None else rng.uniform(0, 360, n))
        yaw = np.radians(rng.uniform(*s.yaw_deg, n))
        self.tilt_deg = np.degrees(np.abs(tilt))
        self.yaw_deg = np.degrees(yaw)
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
        T[:, :3, 3] = self.centre - R @ np.array([w / 2.0, h / 2.0, 0.0])
        self.T_rig_board = T


def plan_board_poses(
    kinematics: DualArmKinematics,
    camera: CameraModel,
    board: ChArUcoBoard,
    T_tcp_board: npt.ArrayLike,
    arm: str,
    current_state: npt.ArrayLike,
    settings: PlannerSettings | None = None,
    seed: int = 0,
    *,
    for_calibration: bool = True,
) -> PosePlan:
    """Choose ``settings.poses`` reachable, visible, diverse board poses for ``arm`` (see the module docstring).

    ``camera`` is the head camera (any resolution: only its field of view and pose matter);
    ``T_tcp_board`` the board mount (nominal for a real rig); ``current_state`` ``(14,)`` the robot's
    state: IK seeds from this arm's joints and the other arm is assumed to hold still there. Raises
    :class:`calib.handeye.DegenerateMotionError` if the chosen poses cannot determine the hand-eye
    transform, ``ValueError`` for bad settings or when no candidate is feasible. ``for_calibration=False``
    (held-out views for a check) skips the motion test.
    """
    s = settings or PlannerSettings()
    mount = _mount(kinematics, arm)
    other = "right" if arm == "left" else "left"
    state = np.asarray(current_state, dtype=np.float64).reshape(STATE_DIM)
    q_start = state[ARM_LAYOUT[arm][0]]
    T_tb = np.asarray(T_tcp_board, dtype=np.float64)
    T_bt = invert_transform(T_tb)
    rng = np.random.default_rng([seed, 0 if arm == "left" else 1, 4711])
    cand = _Candidates(s, arm, camera, board, mount.T_rig_base[:2, 3], rng)
    T_base_rig = invert_transform(mount.T_rig_base)
    obstacles = arm_capsules(getattr(kinematics, other), state[ARM_LAYOUT[other][0]])
    eye = camera.camera_center_in_base()
    corners_b = board.corner_points()
    m = board.margin_m
    w, h = board.size_m
    page_b = np.array([[-m, -m, 0.0], [w + m, -m, 0.0], [w + m, h + m, 0.0], [-m, h + m, 0.0]])
    # The plate must not cut the holding arm's links: a coarse grid over the page (plus the corners).
    gu, gv = np.meshgrid(np.linspace(-m, w + m, 7), np.linspace(-m, h + m, 5))
    plate_b = np.stack([gu.ravel(), gv.ravel(), np.zeros(gu.size)], axis=1)
    margin_u, margin_v = s.image_margin * camera.width, s.image_margin * camera.height
    cos_view = math.cos(math.radians(s.max_view_angle_deg))
    rejected: dict[str, int] = {}
    feasible: list[PlannedPose] = []

    def reject(reason: str) -> None:
        rejected[reason] = rejected.get(reason, 0) + 1

    for k in range(s.candidates):
        T_board = cand.T_rig_board[k]
        R, t = T_board[:3, :3], T_board[:3, 3]
        page = page_b @ R.T + t
        if page[:, 2].min() < _MIN_BOARD_Z:
            reject("below the table")
            continue
        proj = camera.project_detailed(page)
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
        corners = corners_b @ R.T + t
        sight = _unit(eye - corners)
        if np.min(sight @ -R[:, 2]) < cos_view:
            reject("too oblique")
            continue
        T_rig_tcp = T_board @ T_bt
        q = ik_nearest(T_base_rig @ T_rig_tcp, mount.dh, q_start, mount.T_flange_tcp)
        if q is None:
            reject("unreachable")
            continue
        if np.max(np.abs(q[:3] - q_start[:3])) > s.max_arm_joint_move_rad:
            reject("far from the start joints")
            continue
        frames = mount.T_rig_base @ fk_frames(q, mount.dh)
        if frames[1:, 2, 3].min() < _MIN_LINK_Z or T_rig_tcp[2, 3] < _MIN_TCP_Z:
            reject("arm too low")
            continue
        capsules = arm_capsules(mount, q)
        both = capsules + obstacles
        lines = np.concatenate([corners, page])
        dist = segment_distances(np.broadcast_to(eye, lines.shape), lines, both.start, both.end)
        if np.any(dist < both.radius + s.clearance_m):
            reject("line of sight blocked by an arm")
            continue
        links = capsules.links()
        plate = plate_b @ R.T + t
        dist = segment_distances(plate, plate, links.start, links.end)
        if np.any(dist < links.radius + s.clearance_m):
            reject("board cuts through the arm")
            continue
        feasible.append(PlannedPose(q, T_rig_tcp, T_board, float(cand.tilt_deg[k]), float(cand.yaw_deg[k])))
    if not feasible:
        reasons = ", ".join(f"{r}: {c}" for r, c in sorted(rejected.items(), key=lambda x: -x[1]))
        raise ValueError(
            f"pose planner ({arm} arm): none of {s.candidates} candidate board poses is feasible ({reasons})"
        )
    chosen = _farthest_points(feasible, s.poses, s.position_weight_m)
    ordered = visit_order([feasible[i] for i in chosen], q_start)
    motion = None
    if for_calibration:
        try:
            motion = check_motion([p.T_rig_tcp for p in ordered])
        except DegenerateMotionError as exc:
            raise DegenerateMotionError(f"{arm} arm, planned board poses: {exc}") from None
    return PosePlan(
        arm=arm, poses=tuple(ordered), motion=motion, feasible=len(feasible), sampled=s.candidates, rejected=rejected
    )


def _pose_distances(poses: list[PlannedPose], k: int, position_weight_m: float) -> FloatArray:
    R_k, c_k = poses[k].T_rig_board[:3, :3], poses[k].T_rig_board[:3, 3]
    out = np.empty(len(poses))
    for i, p in enumerate(poses):
        angle = rotation_angle(p.T_rig_board[:3, :3] @ R_k.T)
        out[i] = angle + float(np.linalg.norm(p.T_rig_board[:3, 3] - c_k)) / position_weight_m
    return out


def _farthest_points(poses: list[PlannedPose], n: int, position_weight_m: float) -> list[int]:
    """Greedy farthest-point sampling: start with the pose farthest from all others on average."""
    n = min(n, len(poses))
    if len(poses) <= 600:
        D = np.stack([_pose_distances(poses, k, position_weight_m) for k in range(len(poses))])
        first = int(np.argmax(D.sum(axis=1)))
    else:  # avoid the quadratic start on very large candidate sets: start from the first candidate's farthest
        first = int(np.argmax(_pose_distances(poses, 0, position_weight_m)))
    chosen = [first]
    nearest = _pose_distances(poses, first, position_weight_m)
    while len(chosen) < n:
        k = int(np.argmax(nearest))
        chosen.append(k)
        nearest = np.minimum(nearest, _pose_distances(poses, k, position_weight_m))
    return chosen


def visit_order(poses: list[PlannedPose], q_start: FloatArray) -> list[PlannedPose]:
    """Nearest-neighbour tour in joint space from the start joints (shorter, smoother robot moves)."""
    left = list(range(len(poses)))
    order: list[int] = []
    q = q_start
    while left:
        k = min(left, key=lambda i: float(np.max(np.abs(poses[i].q - q))))
        order.append(k)
        left.remove(k)
        q = poses[k].q
    return [poses[i] for i in order]
