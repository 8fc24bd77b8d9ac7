"""Hand-eye calibration of one arm's recorded views, for either camera mount.

The steps are the same for the head camera (eye-to-hand, :func:`calibrate_arm`: the board held by the
arm) and for a wrist camera (eye-in-hand, :func:`calibrate_wrist`: the board on the table, the camera on
the arm); only the mount (:class:`calib.handeye_mount.CameraMount`) changes (docs/calibration.md,
"3. Hand-eye" and "Wrist cameras (eye-in-hand)"):

1. detect the board and solve PnP in every view, FK of the *measured* joints in the rig frame
   (:func:`pilworld.calibration.board_views.detect_views`); views with too few corners or a bad PnP fit
   are skipped with the reason;
2. refuse degenerate motion (:func:`calib.handeye.check_hand_eye_motion`: :class:`DegenerateMotionError`
   naming the arm, or the camera, and the cause; for a wrist camera also the motion to add);
3. run both closed forms (Shah's AX = ZB, Park-Martin's AX = XB, :func:`calib.handeye_solve.solve_hand_eye`)
   and start the Huber refinement (:func:`calib.handeye_refine.refine_hand_eye`) from the one with the lower
   pixel reprojection error;
4. report OpenCV's methods, when the installed cv2 has them, as differences from the result.

A head-camera result is rig-frame ``T_cam_base`` (what the control video uses) and a board mount
``T_tcp_board``; a wrist camera's is ``T_tcp_cam`` and the board pose ``T_rig_board``, and
:meth:`WristHandEye.camera_model` is what ``pilworld calibrate handeye --camera NAME`` writes: a
``pilworld.camera_model/v1`` whose ``T_cam_base`` is ``T_cam_tcp``, the convention of
``wrist_cameras.<name>.file`` in a rig config.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any, Generic, TypeVar

import numpy as np
import numpy.typing as npt

from calib.board import ChArUcoBoard
from calib.camera_model import CameraModel
from calib.handeye import DegenerateMotionError, MotionReport, check_hand_eye_motion
from calib.handeye_mount import CameraMount, TransformName
from calib.handeye_opencv import OpenCvEstimate, opencv_hand_eye
from calib.handeye_refine import (
    HandEyeRefinement,
    RefinedEyeInHand,
    RefinedHandEye,
    hand_eye_residuals,
    refine_hand_eye,
)
from calib.handeye_solve import EyeInHandResult, HandEyeResult, HandEyeSolution, solve_hand_eye
from calib.rotations import pose_difference
from pilworld.calibration.board_views import HandEyeView, detect_views
from pilworld.calibration.recording import RecordedView
from pilworld.geometry import invert_transform
from pilworld.kinematics.dual_arm import DualArmKinematics
from pilworld.types import ARM_SIDES

__all__ = ["ArmHandEye", "ArmSolve", "HandEyeView", "WristHandEye", "calibrate_arm", "calibrate_wrist"]

FloatArray = npt.NDArray[np.float64]
S = TypeVar("S", bound=HandEyeSolution)
R = TypeVar("R", bound=HandEyeRefinement)
A = TypeVar("A", bound="ArmSolve[Any, Any]")


@dataclass(frozen=True, eq=False, kw_only=True)
class ArmSolve(Generic[S, R]):
    """What a hand-eye solve of one arm's views gives, for either mount (``X``: the camera transform)."""

    arm: str
    motion: MotionReport
    refined: R
    closed_form: dict[str, S]  #: "shah" and "park"
    closed_form_rms_px: dict[str, float]  #: pixel RMS of each closed form before refinement
    init_method: str  #: the closed form the refinement started from
    opencv: dict[str, OpenCvEstimate]  #: OpenCV's estimates (empty if cv2 has no hand-eye calls)
    used: tuple[str, ...]  #: views used
    skipped: dict[str, str] = field(default_factory=dict)  #: views skipped and why
    views: tuple[HandEyeView, ...] = field(default=(), repr=False)

    @property
    def residual_rms_px(self) -> float:
        return self.refined.rms_px

    def _summary(self) -> dict[str, Any]:
        """The JSON fields both mounts report (millimetres and degrees), in their order."""
        closed = {}
        for name, result in self.closed_form.items():
            dt, dr = pose_difference(result.X, self.refined.X)
            closed[name] = {
                "rms_px": self.closed_form_rms_px[name],
                "diff_from_refined_mm": dt * 1e3,
                "diff_from_refined_deg": dr,
            }
        return {
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
        }

    def _opencv_summary(self) -> dict[str, Any]:
        return {
            name: {"diff_mm": est.translation_diff_m * 1e3, "diff_deg": est.rotation_diff_deg}
            for name, est in self.opencv.items()
        }


@dataclass(frozen=True, eq=False, kw_only=True)
class ArmHandEye(ArmSolve[HandEyeResult, RefinedHandEye]):
    """The eye-to-hand result of one arm."""

    T_cam_base = TransformName("refined.X", "Refined, rig frame → camera frame.")
    T_tcp_board = TransformName("refined.Y", "Refined, board frame → TCP frame.")

    def to_dict(self) -> dict[str, Any]:
        """A JSON-friendly summary (millimetres and degrees)."""
        return {
            **self._summary(),
            "opencv": self._opencv_summary(),
            "T_cam_base": self.T_cam_base.tolist(),
            "T_tcp_board": self.T_tcp_board.tolist(),
        }


@dataclass(frozen=True, eq=False, kw_only=True)
class WristHandEye(ArmSolve[EyeInHandResult, RefinedEyeInHand]):
    """The eye-in-hand result of one wrist camera (OpenCV's estimates compared on ``T_tcp_cam``)."""

    camera: str  #: the wrist camera's name (e.g. cam_left_wrist)
    intrinsics: CameraModel  #: the intrinsics used, at the images' resolution

    T_tcp_cam = TransformName("refined.X", "Refined: camera-frame points → TCP frame.")
    T_rig_board = TransformName("refined.Y", "Refined: board-frame points → rig frame.")

    @property
    def T_cam_tcp(self) -> FloatArray:  # noqa: N802 - the transform's name
        return invert_transform(self.T_tcp_cam)

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
        return {
            "camera": self.camera,
            "arm": self.arm,
            **self._summary(),
            "uncertainty": self.refined.uncertainty(),
            "opencv": self._opencv_summary(),
            "T_tcp_cam": self.T_tcp_cam.tolist(),
            "T_cam_tcp": self.T_cam_tcp.tolist(),
            "T_rig_board": self.T_rig_board.tolist(),
        }


def _solve(
    result: type[A],
    mount: CameraMount,
    views: Sequence[RecordedView],
    model: CameraModel,
    board: ChArUcoBoard,
    kinematics: DualArmKinematics,
    arm: str,
    *,
    who: str,
    no_views: str | None,
    huber_px: float,
    **extra: Any,
) -> A:
    """Steps 1-4 of the module docstring on ``arm``'s views; a ``result`` with the mount's ``extra`` fields.

    ``model`` holds the intrinsics at the images' resolution (its ``T_cam_base`` is ignored).
    ``who`` names the arm (or the camera) in a refusal; ``no_views``, when given, is the error for an arm
    without views (else the motion check refuses it as too few poses).
    """
    if arm not in ARM_SIDES:
        raise ValueError(f"arm: expected one of {', '.join(ARM_SIDES)}, got {arm!r}")
    mine = [v for v in views if v.arm == arm]
    if not mine and no_views is not None:
        raise ValueError(no_views)
    data, skipped = detect_views(mine, model, board, kinematics, arm)
    G = np.asarray([d.T_base_gripper for d in data]).reshape(-1, 4, 4)
    C = np.asarray([d.T_cam_board for d in data]).reshape(-1, 4, 4)
    try:
        motion = check_hand_eye_motion(mount, G)
    except DegenerateMotionError as exc:
        extra_text = f" ({len(skipped)} of {len(mine)} views skipped: {'; '.join(sorted(set(skipped.values())))})"
        raise DegenerateMotionError(f"{who}: {exc}{extra_text if skipped else ''}") from None
    objs, imgs = [d.board_points for d in data], [d.image_points for d in data]
    K, dist = model.K, model.dist
    closed: dict[str, HandEyeSolution] = {}
    closed_rms: dict[str, float] = {}
    for method in ("shah", "park"):
        solution = solve_hand_eye(mount, G, C, method=method)
        r = hand_eye_residuals(mount, solution.X, solution.Y, G, objs, imgs, K, dist)
        closed[method], closed_rms[method] = solution, math.sqrt(float(np.mean(np.sum(r**2, axis=1))))
    init = min(closed_rms, key=lambda k: closed_rms[k])
    refined = refine_hand_eye(mount, closed[init].X, closed[init].Y, G, objs, imgs, K, dist, huber_px=huber_px)
    return result(
        arm=arm,
        motion=motion,
        refined=refined,
        closed_form=closed,
        closed_form_rms_px=closed_rms,
        init_method=init,
        opencv=opencv_hand_eye(mount, G, C, refined.X),
        used=tuple(d.name for d in data),
        skipped=skipped,
        views=tuple(data),
        **extra,
    )


def calibrate_arm(
    views: Sequence[RecordedView],
    camera: CameraModel,
    board: ChArUcoBoard,
    kinematics: DualArmKinematics,
    arm: str,
    *,
    huber_px: float = 1.0,
) -> ArmHandEye:
    """Eye-to-hand ``T_cam_base`` from ``arm``'s views (see the module docstring).

    ``camera`` holds the intrinsics at the images' resolution (its ``T_cam_base`` is ignored).
    Raises :class:`DegenerateMotionError` (message naming the arm and the cause) for degenerate motion,
    including fewer than 3 usable views.
    """
    mount = CameraMount.EYE_TO_HAND
    return _solve(
        ArmHandEye, mount, views, camera, board, kinematics, arm, who=f"{arm} arm", no_views=None, huber_px=huber_px
    )


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
    no_views = f"{camera}: the recording has no views with the {arm} arm (the arm carrying the camera)"
    mount = CameraMount.EYE_IN_HAND
    return _solve(
        WristHandEye,
        mount,
        views,
        intrinsics,
        board,
        kinematics,
        arm,
        who=f"{camera} ({arm} arm)",
        no_views=no_views,
        huber_px=huber_px,
        camera=camera,
        intrinsics=intrinsics,
    )
