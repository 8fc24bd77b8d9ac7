"""Eye-to-hand calibration of the head camera from recorded board views, per arm and for both arms.

Per arm (:func:`calibrate_arm`):

1. detect the ChArUco corners in every view (:class:`calib.detect.BoardDetector`) and solve PnP with the
   known intrinsics: ``A_i = T_cam_board``; views with too few corners or a bad PnP fit are skipped
   with the reason;
2. FK of the *measured* joints gives ``B_i = T_rig_tcp`` (rig frame, so the result is the rig-frame
   ``T_cam_base`` the control video uses);
3. :func:`calib.handeye.check_motion` refuses degenerate motion (:class:`DegenerateMotionError` naming the
   cause and the arm); both closed forms run (Shah's AX = ZB, Park-Martin's AX = XB) and the one with
   the lower pixel reprojection error starts :func:`calib.handeye_refine.refine_eye_to_hand` (Huber);
4. OpenCV's methods, when the installed cv2 has them, are reported as differences from the result.

Both arms (:func:`calibrate_both`): each arm is solved on its own, the two ``T_cam_base`` are compared
(their disagreement is a direct measure of FK, mount and calibration error), and the combined estimate
is a **joint refinement**: one ``T_cam_base`` and one ``T_tcp_board`` per arm fitted to every corner of
both arms' views (same Huber loss), started from the arm with the lower residual.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any, Final

import cv2
import numpy as np
import numpy.typing as npt

from calib.board import ChArUcoBoard
from calib.camera_model import CameraModel
from calib.detect import BoardDetector
from calib.handeye import DegenerateMotionError, MotionReport, check_motion
from calib.handeye_opencv import OpenCvEstimate, opencv_eye_to_hand
from calib.handeye_refine import RefinedHandEye, refine_eye_to_hand, reprojection_residuals
from calib.handeye_solve import HandEyeResult, solve_eye_to_hand
from calib.rotations import pose_difference, rigid, rotation_exp
from pilworld.calibration.recording import RecordedView
from pilworld.kinematics.dual_arm import DualArmKinematics
from pilworld.types import ARM_LAYOUT, ARM_SIDES

__all__ = [
    "ArmHandEye",
    "BothArmsHandEye",
    "HandEyeOutcome",
    "HandEyeView",
    "calibrate_arm",
    "calibrate_both",
    "refine_shared_camera",
    "solve_recording",
]

FloatArray = npt.NDArray[np.float64]

MIN_CORNERS: Final = 8  #: a view needs this many detected corners (and at least half the board's)
MAX_PNP_RMS_PX: Final = 2.0  #: a view whose own PnP leaves more than this is a bad detection


@dataclass(frozen=True, eq=False)
class HandEyeView:
    """One usable view: FK pose, PnP pose and the detected corners."""

    name: str
    T_base_gripper: FloatArray
    T_cam_board: FloatArray
    board_points: FloatArray
    image_points: FloatArray


@dataclass(frozen=True, eq=False)
class ArmHandEye:
    """The eye-to-hand result of one arm."""

    arm: str
    T_cam_base: FloatArray  #: refined, rig frame → camera frame
    T_tcp_board: FloatArray  #: refined, board frame → TCP frame
    motion: MotionReport
    refined: RefinedHandEye
    closed_form: dict[str, HandEyeResult]  #: "shah" and "park"
    closed_form_rms_px: dict[str, float]  #: pixel RMS of each closed form before refinement
    init_method: str  #: the closed form the refinement started from
    opencv: dict[str, OpenCvEstimate]  #: OpenCV's estimates (empty if cv2 has no hand-eye calls)
    used: tuple[str, ...]  #: views used
    skipped: dict[str, str] = field(default_factory=dict)  #: views skipped and why
    views: tuple[HandEyeView, ...] = field(default=(), repr=False)

    @property
    def residual_rms_px(self) -> float:
        return self.refined.rms_px

    def to_dict(self) -> dict[str, Any]:
        """A JSON-friendly summary (millimetres and degrees)."""
        closed = {}
        for name, result in self.closed_form.items():
            dt, dr = pose_difference(result.T_cam_base, self.T_cam_base)
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
            "opencv": {
                name: {"diff_mm": est.translation_diff_m * 1e3, "diff_deg": est.rotation_diff_deg}
                for name, est in self.opencv.items()
            },
            "T_cam_base": self.T_cam_base.tolist(),
            "T_tcp_board": self.T_tcp_board.tolist(),
        }


def _detect_views(
    views: Sequence[RecordedView], camera: CameraModel, board: ChArUcoBoard, kinematics: DualArmKinematics, arm: str
) -> tuple[list[HandEyeView], dict[str, str]]:
    detector = BoardDetector(board)
    mount = getattr(kinematics, arm)
    min_corners = max(MIN_CORNERS, board.n_corners // 2)
    used: list[HandEyeView] = []
    skipped: dict[str, str] = {}
    for view in views:
        if view.image_size != (camera.width, camera.height):
            raise ValueError(
                f"view {view.name!r}: image is {view.image_size[0]}x{view.image_size[1]} but the camera model is "
                f"{camera.width}x{camera.height}; calibrate intrinsics at the resolution of the hand-eye images"
            )
        detection = detector.detect(view.gray(), name=view.name)
        if detection.n_corners < min_corners:
            skipped[view.name] = f"{detection.n_corners} corners detected (need {min_corners})"
            continue
        obj, img = detection.object_image_points()
        ok, rvec, tvec = cv2.solvePnP(obj, img, camera.K, camera.dist, flags=cv2.SOLVEPNP_ITERATIVE)
        if not ok:
            skipped[view.name] = "PnP failed"
            continue
        proj, _ = cv2.projectPoints(obj, rvec, tvec, camera.K, camera.dist)
        rms = math.sqrt(float(np.mean(np.sum((proj.reshape(-1, 2) - img) ** 2, axis=1))))
        if rms > MAX_PNP_RMS_PX:
            skipped[view.name] = f"PnP reprojection RMS {rms:.2f} px (> {MAX_PNP_RMS_PX} px): a bad detection"
            continue
        T_cam_board = rigid(cv2.Rodrigues(rvec)[0], tvec)
        T_base_gripper = mount.tcp_pose(view.state[ARM_LAYOUT[arm][0]])
        used.append(HandEyeView(view.name, T_base_gripper, T_cam_board, obj, img))
    return used, skipped


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
    if arm not in ARM_SIDES:
        raise ValueError(f"arm: expected one of {', '.join(ARM_SIDES)}, got {arm!r}")
    mine = [v for v in views if v.arm == arm]
    data, skipped = _detect_views(mine, camera, board, kinematics, arm)
    G = np.asarray([d.T_base_gripper for d in data]).reshape(-1, 4, 4)
    C = np.asarray([d.T_cam_board for d in data]).reshape(-1, 4, 4)
    try:
        motion = check_motion(G)
    except DegenerateMotionError as exc:
        extra = f" ({len(skipped)} of {len(mine)} views skipped: {'; '.join(sorted(set(skipped.values())))})"
        raise DegenerateMotionError(f"{arm} arm: {exc}{extra if skipped else ''}") from None
    objs, imgs = [d.board_points for d in data], [d.image_points for d in data]
    closed: dict[str, HandEyeResult] = {}
    closed_rms: dict[str, float] = {}
    for method in ("shah", "park"):
        result = solve_eye_to_hand(G, C, method=method)
        r = reprojection_residuals(result.T_cam_base, result.T_gripper_board, G, objs, imgs, camera.K, camera.dist)
        closed[method], closed_rms[method] = result, math.sqrt(float(np.mean(np.sum(r**2, axis=1))))
    init = min(closed_rms, key=lambda k: closed_rms[k])
    refined = refine_eye_to_hand(
        closed[init].T_cam_base, closed[init].T_gripper_board, G, objs, imgs, camera.K, camera.dist, huber_px=huber_px
    )
    return ArmHandEye(
        arm=arm,
        T_cam_base=refined.T_cam_base,
        T_tcp_board=refined.T_gripper_board,
        motion=motion,
        refined=refined,
        closed_form=closed,
        closed_form_rms_px=closed_rms,
        init_method=init,
        opencv=opencv_eye_to_hand(G, C, reference_T_cam_base=refined.T_cam_base),
        used=tuple(d.name for d in data),
        skipped=skipped,
        views=tuple(data),
    )


# ---------------------------------------------------------------------- both arms


@dataclass(frozen=True, eq=False)
class BothArmsHandEye:
    """Each arm's own result, their disagreement and the joint refinement over both."""

    arms: dict[str, ArmHandEye]
    T_cam_base: FloatArray  #: joint refinement (one camera, one board mount per arm)
    T_tcp_board: dict[str, FloatArray]
    rms_px: float  #: residual RMS of the joint refinement over every corner of both arms
    disagreement_mm: float  #: |t_left - t_right| of the two single-arm T_cam_base
    disagreement_deg: float  #: rotation angle between them
    started_from: str  #: the arm whose single-arm result started the joint refinement

    def to_dict(self) -> dict[str, Any]:
        return {
            "method": "joint refinement of one T_cam_base and one T_tcp_board per arm over both arms' corners "
            f"(Huber), started from the {self.started_from} arm's result",
            "residual_rms_px": self.rms_px,
            "disagreement": {"translation_mm": self.disagreement_mm, "rotation_deg": self.disagreement_deg},
            "T_cam_base": self.T_cam_base.tolist(),
            "T_tcp_board": {arm: T.tolist() for arm, T in self.T_tcp_board.items()},
        }


def calibrate_both(
    views: Sequence[RecordedView],
    camera: CameraModel,
    board: ChArUcoBoard,
    kinematics: DualArmKinematics,
    *,
    huber_px: float = 1.0,
) -> BothArmsHandEye:
    """Calibrate with each arm, compare, then refine one camera over both (see the module docstring)."""
    arms = {arm: calibrate_arm(views, camera, board, kinematics, arm, huber_px=huber_px) for arm in ARM_SIDES}
    dt, dr = pose_difference(arms["left"].T_cam_base, arms["right"].T_cam_base)
    start = min(arms, key=lambda a: arms[a].residual_rms_px)
    X, Ys, rms = refine_shared_camera(
        arms[start].T_cam_base,
        {a: (r.T_tcp_board, list(r.views)) for a, r in arms.items()},
        camera.K,
        camera.dist,
        huber_px=huber_px,
    )
    return BothArmsHandEye(
        arms=arms,
        T_cam_base=X,
        T_tcp_board=Ys,
        rms_px=rms,
        disagreement_mm=dt * 1e3,
        disagreement_deg=dr,
        started_from=start,
    )


def _update(T: FloatArray, p: FloatArray) -> FloatArray:
    return rigid(rotation_exp(p[:3]) @ T[:3, :3], T[:3, 3] + p[3:])


def refine_shared_camera(
    T_cam_base: npt.ArrayLike,
    arms: dict[str, tuple[npt.ArrayLike, list[HandEyeView]]],
    K: npt.ArrayLike,
    dist: npt.ArrayLike,
    *,
    huber_px: float = 1.0,
    max_iterations: int = 50,
) -> tuple[FloatArray, dict[str, FloatArray], float]:
    """One ``T_cam_base`` and one ``T_tcp_board`` per arm fitted to all corners (Huber IRLS Levenberg-Marquardt).

    The same model and update as :func:`calib.handeye_refine.refine_eye_to_hand` (``R ← exp(ω) R``,
    ``t ← t + δ``, central-difference Jacobian), with 6 + 6·arms parameters. Returns the transforms and
    the plain RMS of the corner errors.
    """
    names = list(arms)
    X = np.asarray(T_cam_base, dtype=np.float64)
    Ys = [np.asarray(arms[a][0], dtype=np.float64) for a in names]
    problems = [
        (
            np.asarray([d.T_base_gripper for d in arms[a][1]]),
            [d.board_points for d in arms[a][1]],
            [d.image_points for d in arms[a][1]],
        )
        for a in names
    ]

    def residuals(X: FloatArray, Ys: list[FloatArray]) -> FloatArray:
        parts = [reprojection_residuals(X, Y, G, o, i, K, dist) for Y, (G, o, i) in zip(Ys, problems, strict=True)]
        return np.concatenate(parts)

    def cost(r: FloatArray) -> tuple[float, FloatArray]:
        n = np.linalg.norm(r, axis=1)
        quad = n <= huber_px
        c = float(np.where(quad, 0.5 * n**2, huber_px * (n - 0.5 * huber_px)).sum())
        return c, np.where(quad, 1.0, huber_px / np.maximum(n, 1e-300))

    def apply(step: FloatArray) -> tuple[FloatArray, list[FloatArray]]:
        return _update(X, step[:6]), [_update(Y, step[6 + 6 * k : 12 + 6 * k]) for k, Y in enumerate(Ys)]

    n_par = 6 + 6 * len(names)
    r = residuals(X, Ys)
    c, w = cost(r)
    lam, h = 1e-3, 1e-6
    for _ in range(max_iterations):
        J = np.empty((r.size, n_par))
        for k in range(n_par):
            dp = np.zeros(n_par)
            dp[k] = h
            J[:, k] = ((residuals(*apply(dp)) - residuals(*apply(-dp))) / (2.0 * h)).reshape(-1)
        wr = np.repeat(w, 2)
        H = J.T @ (wr[:, None] * J)
        g = J.T @ (wr * r.reshape(-1))
        improved, decrease = False, 0.0
        while lam < 1e12:
            step = np.asarray(np.linalg.solve(H + lam * np.diag(np.diag(H) + 1e-12), -g), dtype=np.float64)
            X_new, Ys_new = apply(step)
            r_new = residuals(X_new, Ys_new)
            c_new, w_new = cost(r_new)
            if c_new < c:
                improved, decrease = True, (c - c_new) / max(c, 1e-300)
                X, Ys, r, c, w = X_new, Ys_new, r_new, c_new, w_new
                lam = max(lam / 10.0, 1e-12)
                break
            lam *= 10.0
        if not improved or decrease < 1e-12:
            break
    rms = math.sqrt(float(np.mean(np.sum(r**2, axis=1))))
    return X, dict(zip(names, Ys, strict=True)), rms


# ---------------------------------------------------------------------- one entry point


@dataclass(frozen=True, eq=False)
class HandEyeOutcome:
    """What ``pilworld calibrate handeye`` writes: the estimate for ``arm`` (left, right or both)."""

    arm: str
    camera: CameraModel  #: the intrinsics used, with the estimated T_cam_base
    T_tcp_board: dict[str, FloatArray]  #: estimated board mount per arm
    per_arm: dict[str, ArmHandEye]
    both: BothArmsHandEye | None  #: only for arm == "both"

    @property
    def T_cam_base(self) -> FloatArray:  # noqa: N802 - the name every calibration module uses
        return self.camera.T_cam_base

    @property
    def residual_rms_px(self) -> float:
        return self.both.rms_px if self.both is not None else self.per_arm[self.arm].residual_rms_px

    @property
    def rotation_span_deg(self) -> float:
        """The smallest rotation span of the arms used (each arm must determine the camera on its own)."""
        return min(r.motion.rotation_span_deg for r in self.per_arm.values())

    @property
    def poses(self) -> int:
        return sum(len(r.used) for r in self.per_arm.values())


def solve_recording(
    views: Sequence[RecordedView],
    camera: CameraModel,
    board: ChArUcoBoard,
    kinematics: DualArmKinematics,
    arm: str,
    *,
    huber_px: float = 1.0,
) -> HandEyeOutcome:
    """Calibrate with one arm's views (``arm`` = left or right) or with both (``arm`` = both)."""
    if arm == "both":
        both = calibrate_both(views, camera, board, kinematics, huber_px=huber_px)
        return HandEyeOutcome(arm, camera.with_pose(both.T_cam_base), dict(both.T_tcp_board), both.arms, both)
    if arm not in ARM_SIDES:
        raise ValueError(f"arm: expected left, right or both, got {arm!r}")
    result = calibrate_arm(views, camera, board, kinematics, arm, huber_px=huber_px)
    return HandEyeOutcome(arm, camera.with_pose(result.T_cam_base), {arm: result.T_tcp_board}, {arm: result}, None)
