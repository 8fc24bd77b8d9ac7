"""Eye-in-hand calibration of a wrist camera from recorded views of a board fixed on the table.

1. Detect the ChArUco corners in every view taken by the wrist camera and solve PnP with the known
   intrinsics: ``C_i = T_cam_board``. Views with too few corners or a bad PnP fit are skipped with the
   reason (the same detection as the head camera's, :mod:`pilworld.calibration.solve`).
2. FK of the *measured* joints of the camera's arm gives ``G_i = T_rig_tcp``.
3. :func:`calib.handeye_in_hand.check_eye_in_hand_motion` refuses degenerate motion, naming the motion
   to add. Both closed forms run (Shah's AX = ZB, Park-Martin's AX = XB). The one with the lower pixel
   error starts :func:`calib.handeye_in_hand.refine_eye_in_hand` (Huber, with σ of the mount).
4. OpenCV's ``calibrateHandEye`` methods, when the installed cv2 has them, are reported as differences
   from the result (they solve the same eye-in-hand problem).

The result's :meth:`WristHandEye.camera_model` is what ``pilworld calibrate handeye --camera NAME``
writes: a ``pilworld.camera_model/v1`` whose ``T_cam_base`` is ``T_cam_tcp`` (TCP frame → camera), the
convention of ``wrist_cameras.<name>.file`` in a rig config.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import numpy.typing as npt

from calib.board import ChArUcoBoard
from calib.camera_model import CameraModel
from calib.handeye import DegenerateMotionError, MotionReport, check_eye_in_hand_motion
from calib.handeye_opencv import opencv_eye_to_hand
from calib.handeye_refine import RefinedEyeInHand, eye_in_hand_residuals, refine_eye_in_hand
from calib.handeye_solve import EyeInHandResult, solve_eye_in_hand
from calib.rotations import pose_difference
from pilworld.calibration.recording import RecordedView
from pilworld.calibration.solve import HandEyeView, _detect_views
from pilworld.geometry import invert_transform
from pilworld.kinematics.dual_arm import DualArmKinematics
from pilworld.types import ARM_SIDES

__all__ = ["WristHandEye", "calibrate_wrist"]

FloatArray = npt.NDArray[np.float64]


@dataclass(frozen=True, eq=False)
class WristHandEye:
    """The eye-in-hand result of one wrist camera."""

    camera: str  #: the wrist camera's name (e.g. cam_left_wrist)
    arm: str  #: the arm that carries it
    intrinsics: CameraModel  #: the intrinsics used, at the images' resolution
    T_tcp_cam: FloatArray  #: refined: camera-frame points → TCP frame
    T_rig_board: FloatArray  #: refined: board-frame points → rig frame
    motion: MotionReport
    refined: RefinedEyeInHand
    closed_form: dict[str, EyeInHandResult]  #: "shah" and "park"
    closed_form_rms_px: dict[str, float]
    init_method: str
    opencv: dict[str, tuple[float, float]]  #: method → (mm, deg) difference of its T_tcp_cam from ours
    used: tuple[str, ...]
    skipped: dict[str, str] = field(default_factory=dict)
    views: tuple[HandEyeView, ...] = field(default=(), repr=False)

    @property
    def T_cam_tcp(self) -> FloatArray:  # noqa: N802 - the transform's name
        return invert_transform(self.T_tcp_cam)

    @property
    def residual_rms_px(self) -> float:
        return self.refined.rms_px

    def camera_model(self) -> CameraModel:
        """The calibrated wrist camera: the intrinsics with ``T_cam_base := T_cam_tcp``, named after the camera."""
        return CameraModel(
            K=self.intrinsics.K,
            dist=self.intrinsics.dist,
            T_cam_base=self.T_cam_tcp,
            width=self.intrinsics.width,
            height=self.intrinsics.height,
            name=self.camera,
        )

    def to_dict(self) -> dict[str, Any]:
        """A JSON-friendly summary (millimetres and degrees)."""
        closed = {}
        for name, result in self.closed_form.items():
            dt, dr = pose_difference(result.T_tcp_cam, self.T_tcp_cam)
            closed[name] = {
                "rms_px": self.closed_form_rms_px[name],
                "diff_from_refined_mm": dt * 1e3,
                "diff_from_refined_deg": dr,
            }
        return {
            "camera": self.camera,
            "arm": self.arm,
            "poses": len(self.used),
            "skipped": dict(self.skipped),
            "rotation_span_deg": self.motion.rotation_span_deg,
            "axis_spread": self.motion.axis_spread,
            "residual_rms_px": self.refined.rms_px,
            "per_view_rms_px": dict(zip(self.used, self.refined.per_pose_rms_px, strict=True)),
            "closed_form": closed,
            "refined_from": self.init_method,
            "refine_iterations": self.refined.iterations,
            "refine_converged": self.refined.converged,
            "uncertainty": self.refined.uncertainty(),
            "opencv": {name: {"diff_mm": mm, "diff_deg": deg} for name, (mm, deg) in self.opencv.items()},
            "T_tcp_cam": self.T_tcp_cam.tolist(),
            "T_cam_tcp": self.T_cam_tcp.tolist(),
            "T_rig_board": self.T_rig_board.tolist(),
        }


def calibrate_wrist(
    views: Sequence[RecordedView],
    intrinsics: CameraModel,
    board: ChArUcoBoard,
    kinematics: DualArmKinematics,
    arm: str,
    camera: str,
    *,
    huber_px: float = 1.0,
) -> WristHandEye:
    """Eye-in-hand ``T_tcp_cam`` of wrist camera ``camera`` on ``arm`` from ``arm``'s views (module docstring).

    ``intrinsics`` holds the camera's intrinsics at the images' resolution (its ``T_cam_base`` is
    ignored). Raises :class:`DegenerateMotionError` (naming the camera, the cause and the motion to add)
    for degenerate motion, including fewer than 3 usable views.
    """
    if arm not in ARM_SIDES:
        raise ValueError(f"arm: expected one of {', '.join(ARM_SIDES)}, got {arm!r}")
    mine = [v for v in views if v.arm == arm]
    if not mine:
        raise ValueError(f"{camera}: the recording has no views with the {arm} arm (the arm carrying the camera)")
    data, skipped = _detect_views(mine, intrinsics, board, kinematics, arm)
    G = np.asarray([d.T_base_gripper for d in data]).reshape(-1, 4, 4)
    C = np.asarray([d.T_cam_board for d in data]).reshape(-1, 4, 4)
    try:
        motion = check_eye_in_hand_motion(G)
    except DegenerateMotionError as exc:
        extra = f" ({len(skipped)} of {len(mine)} views skipped: {'; '.join(sorted(set(skipped.values())))})"
        raise DegenerateMotionError(f"{camera} ({arm} arm): {exc}{extra if skipped else ''}") from None
    objs, imgs = [d.board_points for d in data], [d.image_points for d in data]
    K, dist = intrinsics.K, intrinsics.dist
    closed: dict[str, EyeInHandResult] = {}
    closed_rms: dict[str, float] = {}
    for method in ("shah", "park"):
        result = solve_eye_in_hand(G, C, method=method)
        r = eye_in_hand_residuals(result.T_tcp_cam, result.T_base_board, G, objs, imgs, K, dist)
        closed[method], closed_rms[method] = result, math.sqrt(float(np.mean(np.sum(r**2, axis=1))))
    init = min(closed_rms, key=lambda k: closed_rms[k])
    refined = refine_eye_in_hand(
        closed[init].T_tcp_cam, closed[init].T_base_board, G, objs, imgs, K, dist, huber_px=huber_px
    )
    # OpenCV's eye-to-hand wrapper on (T_tcp_rig, T_cam_board) estimates T_cam_tcp: the same mapping as
    # the refinement's (calib.handeye_in_hand).
    opencv = {
        name: pose_difference(invert_transform(est.T_cam_base), refined.T_tcp_cam)
        for name, est in opencv_eye_to_hand(invert_transform(G), C).items()
    }
    return WristHandEye(
        camera=camera,
        arm=arm,
        intrinsics=intrinsics,
        T_tcp_cam=refined.T_tcp_cam,
        T_rig_board=refined.T_base_board,
        motion=motion,
        refined=refined,
        closed_form=closed,
        closed_form_rms_px=closed_rms,
        init_method=init,
        opencv={name: (dt * 1e3, dr) for name, (dt, dr) in opencv.items()},
        used=tuple(d.name for d in data),
        skipped=skipped,
        views=tuple(data),
    )
