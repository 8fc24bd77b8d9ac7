"""Plan reachable, diverse robot poses for a hand-eye calibration, for either camera mount.

One planner serves both mounts (:class:`calib.handeye_mount.CameraMount`); what the arm moves differs:

* **eye-to-hand** (:func:`plan_board_poses`): one arm holds the board at a (nominal) ``T_tcp_board`` in
  front of the fixed head camera;
* **eye-in-hand** (:func:`plan_wrist_poses`): the arm carries a wrist camera (nominal mount
  ``T_tcp_cam``) above the board fixed on the table at a (nominal) ``T_rig_board``.

The steps are the same (docs/calibration.md, "3. Hand-eye" and "Wrist cameras (eye-in-hand)"):

1. **Sample** candidate views (:mod:`.plan_sampling`: board poses, or camera poses).
2. **Keep** the candidates that pass every check (:mod:`.plan_filters`: the page inside the image, not too
   oblique, reachable near the start joints, the arm above the table, no line of sight through an arm,
   and the mount's own checks); the rejections are counted by reason.
3. **Choose** ``poses`` of them greedily by farthest-point sampling on the orientation (geodesic angle)
   plus the position (``position_weight_m`` metres count as one radian) of what the arm moves, which
   spreads rotation angles *and* axes, then order them for short joint moves.
4. **Check** the chosen TCP poses with the mount's motion check
   (:func:`calib.handeye.check_hand_eye_motion`), so settings that cannot determine the hand-eye transform
   (tilts of a few degrees, a single tilt axis, fewer than 3 poses, a camera that only slides) raise
   :class:`calib.handeye.DegenerateMotionError` naming the cause before the robot moves.

The result is a :class:`PosePlan`, so :func:`pilworld.calibration.collect.collect_views` drives any
``Robot`` through it.
"""

from __future__ import annotations

from collections.abc import Iterator
from dataclasses import dataclass, field
from typing import Final

import numpy as np
import numpy.typing as npt

from calib.board import ChArUcoBoard
from calib.camera_model import CameraModel
from calib.handeye import DegenerateMotionError, MotionReport, check_hand_eye_motion
from calib.handeye_mount import CameraMount
from calib.rotations import rotation_angle
from pilworld.calibration.plan_filters import CarriedCameraFilters, Filters, HeldBoardFilters, arm_mount
from pilworld.calibration.plan_sampling import Candidate, board_candidates, camera_candidates
from pilworld.calibration.plan_settings import PlannerSettings, WristPlannerSettings
from pilworld.kinematics.dual_arm import DualArmKinematics
from pilworld.types import ARM_LAYOUT, STATE_DIM

__all__ = [
    "PlannedPose",
    "PlannerSettings",
    "PosePlan",
    "WristPlannerSettings",
    "plan_board_poses",
    "plan_wrist_poses",
    "visit_order",
]

FloatArray = npt.NDArray[np.float64]


@dataclass(frozen=True, eq=False)
class PlannedPose:
    """One chosen pose and the joints that reach it."""

    q: FloatArray  #: ``(6,)`` joint angles of the moving arm (radians)
    T_rig_tcp: FloatArray  #: ``(4, 4)`` TCP pose (rig frame) the joints reach
    T_rig_board: FloatArray  #: ``(4, 4)`` nominal board pose (rig frame): held by the TCP, or fixed on the table
    tilt_deg: float  #: angle between the board normal and the line of sight (or the optical axis)
    yaw_deg: float  #: turn about the normal from the nominal in-plane direction (or the camera's roll)


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


@dataclass(frozen=True)
class _MountPlanning:
    """What a mount's planner does differently besides sampling and filtering: messages, random stream, start."""

    planner: str  #: in "none of N candidate … poses is feasible"
    candidates: str
    planned: str  #: prefixes a refusal of the chosen poses' motion
    rng_stream: int  #: the third word of the seed: the mounts draw independent streams
    #: farthest-point sampling starts from the candidate farthest from all others when there are at most this
    #: many (a quadratic cost), else from candidate 0's farthest; the wrist planner always did the latter
    exhaustive_start_up_to: int


_PLANNING: Final = {
    CameraMount.EYE_TO_HAND: _MountPlanning("pose planner", "board", "planned board poses", 4711, 600),
    CameraMount.EYE_IN_HAND: _MountPlanning("wrist pose planner", "camera", "planned wrist-camera poses", 2024, 0),
}


def _plan(
    mount: CameraMount,
    candidates: Iterator[Candidate],
    filters: Filters,
    arm: str,
    settings: PlannerSettings | WristPlannerSettings,
    for_calibration: bool,
) -> PosePlan:
    """Steps 2-4 of the module docstring on ``candidates``."""
    words = _PLANNING[mount]
    rejected: dict[str, int] = {}
    feasible: list[PlannedPose] = []
    held: list[FloatArray] = []
    for c in candidates:
        q = filters.reach(c)
        if isinstance(q, str):  # the reason it is rejected
            rejected[q] = rejected.get(q, 0) + 1
            continue
        feasible.append(PlannedPose(q, c.T_rig_tcp, c.T_rig_board, c.tilt_deg, c.yaw_deg))
        held.append(c.T_rig_held)
    if not feasible:
        reasons = ", ".join(f"{r}: {n}" for r, n in sorted(rejected.items(), key=lambda x: -x[1]))
        raise ValueError(
            f"{words.planner} ({arm} arm): none of {settings.candidates} candidate {words.candidates} poses is "
            f"feasible ({reasons})"
        )
    chosen = _farthest_points(
        np.asarray(held), settings.poses, settings.position_weight_m, words.exhaustive_start_up_to
    )
    ordered = visit_order([feasible[i] for i in chosen], filters.q_start)
    motion = None
    if for_calibration:
        try:
            motion = check_hand_eye_motion(mount, [p.T_rig_tcp for p in ordered])
        except DegenerateMotionError as exc:
            raise DegenerateMotionError(f"{arm} arm, {words.planned}: {exc}") from None
    return PosePlan(
        arm=arm,
        poses=tuple(ordered),
        motion=motion,
        feasible=len(feasible),
        sampled=settings.candidates,
        rejected=rejected,
    )


def _rng(seed: int, arm: str, mount: CameraMount) -> np.random.Generator:
    return np.random.default_rng([seed, 0 if arm == "left" else 1, _PLANNING[mount].rng_stream])


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
    """Eye-to-hand: ``settings.poses`` reachable, visible, diverse board poses for ``arm`` (module docstring).

    ``camera`` is the head camera (any resolution: only its field of view and pose matter);
    ``T_tcp_board`` the board mount (nominal for a real rig); ``current_state`` ``(14,)`` the robot's
    state: IK seeds from this arm's joints and the other arm is assumed to hold still there. Raises
    :class:`calib.handeye.DegenerateMotionError` if the chosen poses cannot determine the hand-eye
    transform, ``ValueError`` for bad settings or when no candidate is feasible. ``for_calibration=False``
    (held-out views for a check) skips the motion test.
    """
    s = settings or PlannerSettings()
    mount = CameraMount.EYE_TO_HAND
    base_xy = arm_mount(kinematics, arm).T_rig_base[:2, 3]
    state = np.asarray(current_state, dtype=np.float64).reshape(STATE_DIM)
    T_tcp_board_ = np.asarray(T_tcp_board, dtype=np.float64)
    candidates = board_candidates(s, arm, camera, board, T_tcp_board_, base_xy, _rng(seed, arm, mount))
    filters = HeldBoardFilters(s, camera, kinematics, arm, state, board)
    return _plan(mount, candidates, filters, arm, s, for_calibration)


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
    """Eye-in-hand: ``settings.poses`` reachable, unoccluded, diverse views of the table board (module docstring).

    ``camera`` is the wrist camera with ``T_cam_base = T_cam_tcp`` (as :meth:`RigConfig.wrist_camera_model`
    returns it; any resolution: only its field of view and mount matter, and they may be nominal);
    ``T_rig_board`` the board's (nominal) pose; ``current_state`` ``(14,)`` the robot's state (IK seeds
    from this arm's joints; the other arm holds still there; the grip and ``max_opening_m``, the gripper's
    stroke, set where the fingers cover the image). Raises
    :class:`calib.handeye.DegenerateMotionError` if the chosen poses cannot determine the mount,
    ``ValueError`` for bad settings or when no candidate is feasible.
    """
    s = settings or WristPlannerSettings()
    mount = CameraMount.EYE_IN_HAND
    arm_ = arm_mount(kinematics, arm)
    state = np.asarray(current_state, dtype=np.float64).reshape(STATE_DIM)
    T_rig_tcp_start = arm_.tcp_pose(state[ARM_LAYOUT[arm][0]])
    T_board = np.asarray(T_rig_board, dtype=np.float64)
    candidates = camera_candidates(s, camera, board, T_board, T_rig_tcp_start, _rng(seed, arm, mount))
    filters = CarriedCameraFilters(s, camera, kinematics, arm, state, board, T_board, max_opening_m)
    return _plan(mount, candidates, filters, arm, s, for_calibration)


def _distances(held: FloatArray, k: int, position_weight_m: float) -> FloatArray:
    """Orientation (radians) plus position (in units of ``position_weight_m``) distance of every pose to pose ``k``."""
    R_k, c_k = held[k, :3, :3], held[k, :3, 3]
    out = np.empty(held.shape[0])
    for i in range(held.shape[0]):
        angle = rotation_angle(held[i, :3, :3] @ R_k.T)
        out[i] = angle + float(np.linalg.norm(held[i, :3, 3] - c_k)) / position_weight_m
    return out


def _farthest_points(held: FloatArray, n: int, position_weight_m: float, exhaustive_start_up_to: int) -> list[int]:
    """Greedy farthest-point sampling of ``n`` of the ``(N, 4, 4)`` poses ``held``."""
    n = min(n, held.shape[0])
    if held.shape[0] <= exhaustive_start_up_to:  # the pose farthest from all others on average
        D = np.stack([_distances(held, k, position_weight_m) for k in range(held.shape[0])])
        first = int(np.argmax(D.sum(axis=1)))
    else:  # avoid the quadratic start on large candidate sets: start from the first candidate's farthest
        first = int(np.argmax(_distances(held, 0, position_weight_m)))
    chosen = [first]
    nearest = _distances(held, first, position_weight_m)
    while len(chosen) < n:
        k = int(np.argmax(nearest))
        chosen.append(k)
        nearest = np.minimum(nearest, _distances(held, k, position_weight_m))
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
