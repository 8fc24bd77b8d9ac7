"""Hand-eye calibration on the simulated rig, where the answer is known: the acceptance run and its pieces.

The simulated head camera renders board images at a calibration resolution (``resolution`` pixels wide,
the same field of view as the rig's camera, so the intrinsics scale exactly); a :class:`BoardMount`
puts the board on the calibrating arm's TCP; the planner, the collector and the solver are the ones a
real rig uses. Ground truth: ``T_cam_base`` from ``rig.head_camera_model`` and ``T_tcp_board`` from
the mount. :func:`run_sim_handeye` is what ``pilworld bench`` calls.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any, Final

import numpy as np
import numpy.typing as npt

from calib.board import ChArUcoBoard
from calib.camera_model import CameraModel
from calib.rotations import pose_difference
from pilworld.calibration.check import gripper_reprojection_errors
from pilworld.calibration.collect import collect_views
from pilworld.calibration.plan import PlannerSettings, plan_board_poses
from pilworld.calibration.recording import RecordedView, Recording, SimTruth
from pilworld.calibration.solve_arms import HandEyeOutcome, solve_recording
from pilworld.config.rig import RigConfig
from pilworld.types import ARM_SIDES, HEAD_VIEW
from simrig.board_mount import BoardMount
from simrig.poses import HOME_Q14
from simrig.robot import SimRobot

__all__ = [
    "DEFAULT_BOARD",
    "arms_for",
    "held_out_states",
    "record_sim",
    "run_sim_handeye",
    "sim_calibration_camera",
    "truth_errors",
]

FloatArray = npt.NDArray[np.float64]

DEFAULT_BOARD: Final = Path(__file__).resolve().parents[2] / "configs" / "board" / "charuco_7x5_a4.yaml"
#: The held-out planner seed is the calibration seed plus this, so held-out poses never repeat calibration ones.
HELD_OUT_SEED_OFFSET: Final = 1000


def arms_for(arm: str) -> tuple[str, ...]:
    """``left`` → (left,), ``right`` → (right,), ``both`` → (left, right)."""
    if arm == "both":
        return ARM_SIDES
    if arm not in ARM_SIDES:
        raise ValueError(f"arm: expected left, right or both, got {arm!r}")
    return (arm,)


def sim_calibration_camera(rig: RigConfig, resolution: int) -> CameraModel:
    """The simulated head camera rendered ``resolution`` pixels wide with the same field of view (true intrinsics).

    MuJoCo's ``fovy`` spans the image height and pixels are square, so ``f`` scales with the height and
    the principal point stays at the image centre.
    """
    if isinstance(resolution, bool) or not isinstance(resolution, int) or not 16 <= resolution <= 8192:
        raise ValueError(f"resolution: expected an image width in pixels, 16..8192, got {resolution!r}")
    cam = rig.head_camera_model
    width = resolution
    height = round(resolution * cam.height / cam.width)
    f = float(cam.K[1, 1]) * height / cam.height
    K = np.array([[f, 0.0, (width - 1) / 2.0], [0.0, f, (height - 1) / 2.0], [0.0, 0.0, 1.0]])
    return CameraModel(K=K, dist=np.zeros(0), T_cam_base=cam.T_cam_base, width=width, height=height, name=cam.name)


def record_sim(
    rig: RigConfig,
    arm: str = "left",
    *,
    board: ChArUcoBoard | None = None,
    poses: int = 20,
    seed: int = 0,
    resolution: int = 1024,
    settings: PlannerSettings | None = None,
    log: Callable[[str], None] | None = None,
    for_calibration: bool = True,
) -> Recording:
    """Plan, move the simulated rig and render board views with ``arm`` (left, right or both).

    With both arms the board is mounted on one arm at a time (a second simulator instance), as an operator
    would move it. The recording's camera holds the true intrinsics at the calibration resolution (with an
    identity ``T_cam_base``: that is what is being calibrated) and its truth the camera pose and mounts.
    ``for_calibration=False`` (held-out views for a check) lets the planner skip its motion test.
    """
    board = board or ChArUcoBoard.from_yaml(DEFAULT_BOARD)
    camera = sim_calibration_camera(rig, resolution)
    settings = settings or PlannerSettings(poses=poses)
    views: list[RecordedView] = []
    mounts: dict[str, FloatArray] = {}
    for side in arms_for(arm):
        mount = BoardMount.beside_tcp(board, side)
        mounts[side] = np.asarray(mount.T_tcp_board)
        with SimRobot(rig, board_mount=mount) as robot:
            state = np.asarray(robot.observe().state, dtype=np.float64)
            plan = plan_board_poses(
                rig.kinematics,
                camera,
                board,
                mount.T_tcp_board,
                side,
                state,
                settings,
                seed,
                for_calibration=for_calibration,
            )
            if log is not None:
                log(plan.summary())

            def capture(robot: SimRobot = robot) -> npt.NDArray[np.uint8]:
                return robot.render(HEAD_VIEW, camera.width, camera.height)

            views += collect_views(robot, plan, capture, log=log)
    return Recording(
        rig=rig.name,
        board=board,
        views=tuple(views),
        camera=camera.with_pose(np.eye(4)),
        truth=SimTruth(T_cam_base=np.asarray(rig.head_camera_model.T_cam_base), T_tcp_board=mounts),
        extra={"source": "simulated rig", "seed": seed, "resolution": resolution},
    )


def held_out_states(rig: RigConfig, arms: Sequence[str], board: ChArUcoBoard, seed: int, poses: int = 20) -> FloatArray:
    """``(N, 14)`` joint states of board poses planned with another seed (the other arm at home)."""
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


def truth_errors(rig: RigConfig, outcome: HandEyeOutcome, truth: SimTruth, states: npt.ArrayLike) -> dict[str, Any]:
    """True errors of a simulated calibration: camera pose, board mounts and gripper points at the rig's size."""
    dt, dr = pose_difference(outcome.T_cam_base, truth.T_cam_base)
    small = rig.head_camera_model  # the true camera at the rig's image size
    errs = gripper_reprojection_errors(rig, small, outcome.T_cam_base, states)
    every = np.concatenate(list(errs.values()))
    out: dict[str, Any] = {
        "translation_err_mm": dt * 1e3,
        "rotation_err_deg": dr,
        "gripper_reproj_err_px": float(every.max()) if every.size else math.nan,
        "gripper_reproj_mean_px": float(every.mean()) if every.size else math.nan,
        "gripper_points": int(every.size),
        "gripper_image_size": [small.width, small.height],
        "gripper_reproj_err_px_per_arm": {s: float(e.max()) if e.size else math.nan for s, e in errs.items()},
        "board_mount_err": {},
    }
    for side, T in outcome.T_tcp_board.items():
        if side in truth.T_tcp_board:
            mt, mr = pose_difference(T, truth.T_tcp_board[side])
            out["board_mount_err"][side] = {"translation_mm": mt * 1e3, "rotation_deg": mr}
    return out


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
