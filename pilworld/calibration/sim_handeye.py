"""Hand-eye calibration on the simulated rig, where the answer is known: recordings and the acceptance runs.

Both camera mounts run the same steps a real rig does: the planner (:mod:`.plan`), the collector
(:func:`pilworld.calibration.collect.collect_views`, through the ``Robot`` contract) and the solver
(:mod:`.solve`), with the simulator rendering the views at a calibration resolution (``resolution``
pixels wide, the rig's field of view, so the intrinsics scale exactly, :mod:`.sim_cameras`):

* **head camera** (eye-to-hand, :func:`record_sim`): a :class:`simrig.board_mount.BoardMount` puts the
  board on the calibrating arm's TCP (one arm at a time, as an operator would move it);
* **wrist camera** (eye-in-hand, :func:`record_sim_wrist`): a :class:`simrig.table_board.TableBoard` lies
  flat on the table beside the tasks' objects, which are moved to the far edge of the table so they never
  cover it.

Ground truth (:mod:`.sim_truth`) comes from the rig config and the board's placement.
:func:`run_sim_handeye` and :func:`run_sim_wrist` are what ``pilworld bench calibration`` calls
(docs/calibration.md, "Measured on the simulated rig" and "Wrist cameras (eye-in-hand)").
"""

from __future__ import annotations

import time
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Final

import numpy as np
import numpy.typing as npt

from calib.board import ChArUcoBoard
from calib.camera_model import CameraModel
from pilworld.calibration.collect import collect_views
from pilworld.calibration.plan import (
    PlannerSettings,
    PosePlan,
    WristPlannerSettings,
    plan_board_poses,
    plan_wrist_poses,
)
from pilworld.calibration.recording import RecordedView, Recording, SimTruth
from pilworld.calibration.sim_cameras import sim_calibration_camera, sim_wrist_camera, wrist_arm
from pilworld.calibration.sim_truth import TRUTH_KEY, WristTruth, truth_errors, wrist_truth_errors
from pilworld.calibration.solve import calibrate_wrist
from pilworld.calibration.solve_arms import solve_recording
from pilworld.config.rig import RigConfig
from pilworld.types import ARM_SIDES, HEAD_VIEW
from simrig.board_mount import BoardMount
from simrig.poses import HOME_Q14
from simrig.robot import SimRobot
from simrig.table_board import TableBoard
from simrig.tasks import ObjectPose

__all__ = [
    "DEFAULT_BOARD",
    "HELD_OUT_SEED_OFFSET",
    "arms_for",
    "held_out_states",
    "record_sim",
    "record_sim_wrist",
    "record_wrist_check_sim",
    "run_sim_handeye",
    "run_sim_wrist",
]

FloatArray = npt.NDArray[np.float64]
Log = Callable[[str], None] | None

DEFAULT_BOARD: Final = Path(__file__).resolve().parents[2] / "configs" / "board" / "charuco_7x5_a4.yaml"
#: The held-out planner seed is the calibration seed plus this, so held-out poses never repeat calibration ones.
HELD_OUT_SEED_OFFSET: Final = 1000
#: Where the tasks' objects are parked during a wrist calibration: the far edge of the table.
_PARKED_X: Final = 0.42
_PARKED_YS: Final = (-0.12, 0.0, 0.12, -0.24, 0.24)


def arms_for(arm: str) -> tuple[str, ...]:
    """``left`` → (left,), ``right`` → (right,), ``both`` → (left, right)."""
    if arm == "both":
        return ARM_SIDES
    if arm not in ARM_SIDES:
        raise ValueError(f"arm: expected left, right or both, got {arm!r}")
    return (arm,)


def _collect(
    robot: SimRobot,
    plan_from: Callable[[FloatArray], PosePlan],
    describe: Callable[[PosePlan], str],
    view: str,
    camera: CameraModel,
    log: Log,
) -> list[RecordedView]:
    """Plan from the robot's state, say what was planned, then visit the poses rendering ``view`` as ``camera``."""
    plan = plan_from(np.asarray(robot.observe().state, dtype=np.float64))
    if log is not None:
        log(describe(plan))

    def capture() -> npt.NDArray[np.uint8]:
        return robot.render(view, camera.width, camera.height)

    return collect_views(robot, plan, capture, log=log)


def record_sim(
    rig: RigConfig,
    arm: str = "left",
    *,
    board: ChArUcoBoard | None = None,
    poses: int = 20,
    seed: int = 0,
    resolution: int = 1024,
    settings: PlannerSettings | None = None,
    log: Log = None,
    for_calibration: bool = True,
) -> Recording:
    """Head camera: plan, move the simulated rig and render board views with ``arm`` (left, right or both).

    With both arms the board is mounted on one arm at a time (a second simulator instance). The recording's
    camera holds the true intrinsics at the calibration resolution (with an identity ``T_cam_base``: that
    is what is being calibrated) and its truth the camera pose and mounts. ``for_calibration=False``
    (held-out views for a check) lets the planner skip its motion test.
    """
    board = board or ChArUcoBoard.from_yaml(DEFAULT_BOARD)
    camera = sim_calibration_camera(rig, resolution)
    settings = settings or PlannerSettings(poses=poses)
    views: list[RecordedView] = []
    mounts: dict[str, FloatArray] = {}
    for side in arms_for(arm):
        mount = BoardMount.beside_tcp(board, side)
        mounts[side] = np.asarray(mount.T_tcp_board)

        def plan_from(state: FloatArray, side: str = side, mount: BoardMount = mount) -> PosePlan:
            return plan_board_poses(
                rig.kinematics, camera, board, mount.T_tcp_board, side, state, settings, seed,
                for_calibration=for_calibration,
            )  # fmt: skip

        with SimRobot(rig, board_mount=mount) as robot:
            views += _collect(robot, plan_from, PosePlan.summary, HEAD_VIEW, camera, log)
    return Recording(
        rig=rig.name,
        board=board,
        views=tuple(views),
        camera=camera.with_pose(np.eye(4)),
        truth=SimTruth(T_cam_base=np.asarray(rig.head_camera_model.T_cam_base), T_tcp_board=mounts),
        extra={"source": "simulated rig", "seed": seed, "resolution": resolution},
    )


def _park_objects(robot: SimRobot) -> None:
    poses = robot.object_poses()
    parked = {}
    for k, (name, pose) in enumerate(poses.items()):
        y = _PARKED_YS[k % len(_PARKED_YS)]
        parked[name] = ObjectPose((_PARKED_X, y, pose.xyz[2]), pose.quat)
    robot.set_object_poses(parked)


def record_sim_wrist(
    rig: RigConfig,
    camera: str,
    *,
    board: ChArUcoBoard | None = None,
    poses: int = 20,
    seed: int = 0,
    resolution: int = 1024,
    settings: WristPlannerSettings | None = None,
    log: Log = None,
    for_calibration: bool = True,
) -> Recording:
    """Wrist camera: plan, move the simulated rig and render ``camera``'s views of a board on the table.

    The recording's camera holds the true intrinsics at the calibration resolution (with an identity
    ``T_cam_base``: that is what is being calibrated); its ``extra`` holds the camera's name and the truth
    (:data:`TRUTH_KEY`). ``for_calibration=False`` (held-out views for a check) skips the planner's motion
    test and labels the recording ``eye_in_hand_check``.
    """
    board = board or ChArUcoBoard.from_yaml(DEFAULT_BOARD)
    arm = wrist_arm(rig, camera)
    cam = sim_wrist_camera(rig, camera, resolution)
    settings = settings or WristPlannerSettings(poses=poses)
    table = TableBoard.for_arm(board, arm)
    gripper = getattr(rig.arms, arm).gripper.max_opening_m

    def plan_from(state: FloatArray) -> PosePlan:
        return plan_wrist_poses(
            rig.kinematics, cam, board, table.T_rig_board, arm, state, settings, seed, max_opening_m=gripper,
            for_calibration=for_calibration,
        )  # fmt: skip

    def describe(plan: PosePlan) -> str:
        if not for_calibration:
            return f"{camera} ({arm} arm): {len(plan.poses)} held-out camera poses (planner seed {seed})"
        motion = plan.motion
        spans = "" if motion is None else f"; rotation span {motion.rotation_span_deg:.1f}°, axis spread "
        spans += "" if motion is None else f"{motion.axis_spread:.2f}"
        return f"{camera} ({arm} arm): {len(plan.poses)} camera poses chosen from {plan.feasible} feasible{spans}"

    with SimRobot(rig, table_board=table) as robot:
        _park_objects(robot)
        views = _collect(robot, plan_from, describe, camera, cam, log)
    truth = WristTruth(
        camera=camera, T_tcp_cam=rig.wrist_cameras[camera].pose_in_tcp.matrix(), T_rig_board=table.T_rig_board
    )
    return Recording(
        rig=rig.name,
        board=board,
        views=tuple(views),
        camera=cam.with_pose(np.eye(4)),
        truth=None,
        extra={
            "source": "simulated rig",
            "calibration": "eye_in_hand" if for_calibration else "eye_in_hand_check",
            "camera": camera,
            "seed": seed,
            "resolution": resolution,
            TRUTH_KEY: truth.to_dict(),
        },
    )


def record_wrist_check_sim(
    rig: RigConfig,
    camera: str,
    *,
    board: ChArUcoBoard | None = None,
    poses: int = 6,
    seed: int = 0,
    resolution: int = 1024,
    log: Log = None,
) -> tuple[Recording, FloatArray]:
    """Held-out wrist-camera views of the table board on the simulated rig; returns them and ``T_rig_board``.

    ``seed`` is the calibration's: the planner runs with ``seed + HELD_OUT_SEED_OFFSET``. It plans with the
    camera's designed mount (so a wrong calibration is checked on the same views as a good one) and skips
    the motion test (these views calibrate nothing). The rendering is the true camera at ``resolution``
    pixels wide; the recording carries the truth like :func:`record_sim_wrist`.
    """
    if isinstance(poses, bool) or not isinstance(poses, int) or poses < 1:
        raise ValueError(f"--poses: expected a number of camera poses >= 1, got {poses!r}")
    board = board or ChArUcoBoard.from_yaml(DEFAULT_BOARD)
    recording = record_sim_wrist(
        rig, camera, board=board, poses=poses, seed=seed + HELD_OUT_SEED_OFFSET, resolution=resolution, log=log,
        for_calibration=False,
    )  # fmt: skip
    return recording, np.array(TableBoard.for_arm(board, wrist_arm(rig, camera)).T_rig_board, dtype=np.float64)


def held_out_states(rig: RigConfig, arms: Sequence[str], board: ChArUcoBoard, seed: int, poses: int = 20) -> FloatArray:
    """``(N, 14)`` joint states of head-camera board poses planned with another seed (the other arm at home)."""
    states = [HOME_Q14[None]]
    for side in arms:
        mount = BoardMount.beside_tcp(board, side)
        plan = plan_board_poses(
            rig.kinematics,
            rig.head_camera_model,
            board,
            mount.T_tcp_board,
            side,
            HOME_Q14,
            PlannerSettings(poses=poses),
            seed + HELD_OUT_SEED_OFFSET,
            for_calibration=False,
        )
        states.append(plan.states(HOME_Q14))
    return np.concatenate(states)


def run_sim_handeye(
    rig: RigConfig, arm: str = "left", *, poses: int = 20, seed: int = 0, resolution: int = 1024
) -> dict[str, float]:
    """Calibrate the simulated rig's head camera with ``arm`` and compare with the truth.

    Returns ``handeye_trans_err_mm``, ``handeye_rot_err_deg``, ``gripper_reproj_err_px`` (largest error of
    the FK-projected gripper points of held-out poses at the rig's image size, estimated vs true
    ``T_cam_base``), ``gripper_reproj_mean_px``, ``rotation_span_deg``, ``poses`` (views used),
    ``residual_rms_px`` (corner reprojection after refinement, at ``resolution``), ``seconds``, and for
    ``arm="both"`` also ``disagreement_mm`` and ``disagreement_deg`` between the two arms' estimates.
    """
    t0 = time.perf_counter()
    board = ChArUcoBoard.from_yaml(DEFAULT_BOARD)
    recording = record_sim(rig, arm, board=board, poses=poses, seed=seed, resolution=resolution)
    assert recording.camera is not None and recording.truth is not None  # record_sim sets both
    outcome = solve_recording(recording.views, recording.camera, board, rig.kinematics, arm)
    truth = truth_errors(rig, outcome, recording.truth, held_out_states(rig, arms_for(arm), board, seed))
    out = {
        "handeye_trans_err_mm": float(truth["translation_err_mm"]),
        "handeye_rot_err_deg": float(truth["rotation_err_deg"]),
        "gripper_reproj_err_px": float(truth["gripper_reproj_err_px"]),
        "gripper_reproj_mean_px": float(truth["gripper_reproj_mean_px"]),
        "rotation_span_deg": outcome.rotation_span_deg,
        "poses": float(outcome.poses),
        "residual_rms_px": outcome.residual_rms_px,
    }
    if outcome.both is not None:
        out["disagreement_mm"] = outcome.both.disagreement_mm
        out["disagreement_deg"] = outcome.both.disagreement_deg
    out["seconds"] = time.perf_counter() - t0
    return out


def run_sim_wrist(
    rig: RigConfig, camera: str, *, poses: int = 20, seed: int = 0, resolution: int = 1024
) -> dict[str, float]:
    """Calibrate the simulated rig's wrist camera ``camera`` and compare with the truth.

    Returns ``wrist_trans_err_mm``, ``wrist_rot_err_deg``, ``board_reproj_err_px`` (rig image size),
    ``sigma_translation_mm``, ``sigma_rotation_deg`` (the refinement's own uncertainty),
    ``rotation_span_deg``, ``axis_spread``, ``poses`` (views used), ``residual_rms_px`` (at
    ``resolution``) and ``seconds``.
    """
    t0 = time.perf_counter()
    board = ChArUcoBoard.from_yaml(DEFAULT_BOARD)
    recording = record_sim_wrist(rig, camera, board=board, poses=poses, seed=seed, resolution=resolution)
    assert recording.camera is not None  # record_sim_wrist sets it
    truth = WristTruth.from_extra(recording.extra)
    assert truth is not None
    result = calibrate_wrist(recording.views, recording.camera, board, rig.kinematics, wrist_arm(rig, camera), camera)
    errors = wrist_truth_errors(rig, result, truth)
    u = result.refined.uncertainty()
    return {
        "wrist_trans_err_mm": float(errors["translation_err_mm"]),
        "wrist_rot_err_deg": float(errors["rotation_err_deg"]),
        "board_reproj_err_px": float(errors["board_reproj_err_px"]),
        "sigma_translation_mm": float(u["sigma_translation_mm"]),
        "sigma_rotation_deg": float(u["sigma_rotation_deg"]),
        "rotation_span_deg": result.motion.rotation_span_deg,
        "axis_spread": result.motion.axis_spread,
        "poses": float(len(result.used)),
        "residual_rms_px": result.residual_rms_px,
        "seconds": time.perf_counter() - t0,
    }
