"""Eye-in-hand calibration of a wrist camera on the simulated rig, where the answer is known.

A :class:`simrig.table_board.TableBoard` lies flat on the table beside the tasks' objects (which
are moved to the far edge of the table so they never cover it); the wrist camera renders at a
calibration resolution (``resolution`` pixels wide, the rig's field of view, so the intrinsics scale
exactly); the planner (:mod:`.plan`), the collector (:func:`pilworld.calibration.collect.collect_views`)
and the solver (:mod:`.solve`) are the ones a real rig uses. Ground truth: ``T_tcp_cam`` is the
camera's ``pose_in_tcp`` in the rig config and ``T_rig_board`` is the table board's pose.
:func:`run_sim_wrist` is what ``pilworld bench calibration`` calls.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from typing import Any, Final

import numpy as np
import numpy.typing as npt

from calib.board import ChArUcoBoard
from calib.camera_model import CameraModel
from calib.rotations import pose_difference
from pilworld.calibration.collect import collect_views
from pilworld.calibration.plan import WristPlannerSettings, plan_wrist_poses
from pilworld.calibration.recording import Recording
from pilworld.calibration.sim_handeye import DEFAULT_BOARD
from pilworld.calibration.solve import WristHandEye, calibrate_wrist
from pilworld.config.rig import RigConfig
from pilworld.geometry import invert_transform
from simrig.robot import SimRobot
from simrig.table_board import TableBoard
from simrig.tasks import ObjectPose

__all__ = [
    "TRUTH_KEY",
    "WristTruth",
    "record_sim_wrist",
    "run_sim_wrist",
    "sim_wrist_camera",
    "wrist_arm",
    "wrist_truth_errors",
]

FloatArray = npt.NDArray[np.float64]

#: Key of the eye-in-hand ground truth in a recording's ``poses.json`` (simulated rigs only).
TRUTH_KEY: Final = "sim_truth_eye_in_hand"
#: Where the tasks' objects are parked during a wrist calibration: the far edge of the table.
_PARKED_X: Final = 0.42
_PARKED_YS: Final = (-0.12, 0.0, 0.12, -0.24, 0.24)


@dataclass(frozen=True, eq=False)
class WristTruth:
    """The ground truth of a simulated wrist calibration."""

    camera: str
    T_tcp_cam: FloatArray  #: ``(4, 4)`` camera frame → TCP frame
    T_rig_board: FloatArray  #: ``(4, 4)`` board frame → rig frame

    def to_dict(self) -> dict[str, Any]:
        return {"camera": self.camera, "T_tcp_cam": self.T_tcp_cam.tolist(), "T_rig_board": self.T_rig_board.tolist()}

    @classmethod
    def from_extra(cls, extra: Mapping[str, Any]) -> WristTruth | None:
        """The truth kept in a recording's free-form metadata, or None (a real rig's recording)."""
        doc = extra.get(TRUTH_KEY)
        if not isinstance(doc, Mapping):
            return None
        return cls(
            camera=str(doc["camera"]),
            T_tcp_cam=np.asarray(doc["T_tcp_cam"], dtype=np.float64).reshape(4, 4),
            T_rig_board=np.asarray(doc["T_rig_board"], dtype=np.float64).reshape(4, 4),
        )


def wrist_arm(rig: RigConfig, camera: str) -> str:
    """The arm carrying wrist camera ``camera``; ``ValueError`` listing the rig's cameras otherwise."""
    if camera not in rig.wrist_cameras:
        raise ValueError(
            f"--camera: unknown camera {camera!r}; rig {rig.name!r} has cameras {', '.join(rig.cameras)} "
            f"(wrist cameras: {', '.join(rig.wrist_cameras) or 'none'})"
        )
    return rig.wrist_cameras[camera].arm


def sim_wrist_camera(rig: RigConfig, camera: str, resolution: int) -> CameraModel:
    """The *designed* wrist camera ``resolution`` pixels wide (true intrinsics; ``T_cam_base = T_cam_tcp``).

    As the simulator renders it: an undistorted pinhole of ``fovy_deg`` across the image height, square
    pixels, centred principal point, at ``pose_in_tcp`` (a ``file:`` in the rig config is ignored: the
    simulator places the camera at its designed mount).
    """
    if isinstance(resolution, bool) or not isinstance(resolution, int) or not 16 <= resolution <= 8192:
        raise ValueError(f"resolution: expected an image width in pixels, 16..8192, got {resolution!r}")
    wrist_arm(rig, camera)
    cam = rig.wrist_cameras[camera]
    width = resolution
    height = round(resolution * rig.image_size.height / rig.image_size.width)
    f = height / (2.0 * math.tan(math.radians(cam.fovy_deg) / 2.0))
    K = np.array([[f, 0.0, (width - 1) / 2.0], [0.0, f, (height - 1) / 2.0], [0.0, 0.0, 1.0]])
    T_cam_tcp = invert_transform(cam.pose_in_tcp.matrix())
    return CameraModel(K=K, dist=np.zeros(0), T_cam_base=T_cam_tcp, width=width, height=height, name=camera)


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
    log: Callable[[str], None] | None = None,
) -> Recording:
    """Plan, move the simulated rig and render wrist-camera views of a board on the table.

    The recording's camera holds the true intrinsics at the calibration resolution (with an identity
    ``T_cam_base``: that is what is being calibrated); its ``extra`` holds the camera's name and the truth
    (:data:`TRUTH_KEY`).
    """
    board = board or ChArUcoBoard.from_yaml(DEFAULT_BOARD)
    arm = wrist_arm(rig, camera)
    cam = sim_wrist_camera(rig, camera, resolution)
    settings = settings or WristPlannerSettings(poses=poses)
    table = TableBoard.for_arm(board, arm)
    with SimRobot(rig, table_board=table) as robot:
        _park_objects(robot)
        state = np.asarray(robot.observe().state, dtype=np.float64)
        gripper = getattr(rig.arms, arm).gripper.max_opening_m
        plan = plan_wrist_poses(
            rig.kinematics, cam, board, table.T_rig_board, arm, state, settings, seed, max_opening_m=gripper
        )
        if log is not None:
            motion = plan.motion
            spans = "" if motion is None else f"; rotation span {motion.rotation_span_deg:.1f}°, axis spread "
            spans += "" if motion is None else f"{motion.axis_spread:.2f}"
            log(f"{camera} ({arm} arm): {len(plan.poses)} camera poses chosen from {plan.feasible} feasible{spans}")

        def capture() -> npt.NDArray[np.uint8]:
            return robot.render(camera, cam.width, cam.height)

        views = collect_views(robot, plan, capture, log=log)
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
            "calibration": "eye_in_hand",
            "camera": camera,
            "seed": seed,
            "resolution": resolution,
            TRUTH_KEY: truth.to_dict(),
        },
    )


def wrist_truth_errors(rig: RigConfig, result: WristHandEye, truth: WristTruth) -> dict[str, Any]:
    """True errors: the mount, the board pose, and the board corners drawn at the rig's image size.

    ``board_reproj_err_px``: the largest distance, at the rig's image size (what the control video
    draws), between the board corners projected with the estimated and with the true camera at every
    calibration pose (measured joints).
    """
    dt, dr = pose_difference(result.T_tcp_cam, truth.T_tcp_cam)
    bt, br = pose_difference(result.T_rig_board, truth.T_rig_board)
    small = sim_wrist_camera(rig, truth.camera, rig.image_size.width)
    worst = 0.0
    for view in result.views:
        corners = view.board_points @ truth.T_rig_board[:3, :3].T + truth.T_rig_board[:3, 3]
        T_cam_rig_true = invert_transform(view.T_base_gripper @ truth.T_tcp_cam)
        T_cam_rig_est = invert_transform(view.T_base_gripper @ result.T_tcp_cam)
        uv_true = small.with_pose(T_cam_rig_true).project(corners)[0]
        uv_est = small.with_pose(T_cam_rig_est).project(corners)[0]
        worst = max(worst, float(np.linalg.norm(uv_est - uv_true, axis=1).max()))
    return {
        "translation_err_mm": dt * 1e3,
        "rotation_err_deg": dr,
        "board_pose_err": {"translation_mm": bt * 1e3, "rotation_deg": br},
        "board_reproj_err_px": worst,
        "board_reproj_image_size": [small.width, small.height],
    }


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
