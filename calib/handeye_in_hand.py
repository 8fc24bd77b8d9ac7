"""Eye-in-hand calibration of a wrist camera with a board fixed on the table: AX = XB, AX = ZB and pixel refinement.

Inputs, for each pose ``i`` (N >= 3):

* ``T_base_tcp[i]`` (4x4): forward kinematics of the arm carrying the camera, TCP-frame points → base (or
  rig) frame;
* ``T_cam_board[i]`` (4x4): board-frame points → camera frame (``solvePnP``).

Model: ``T_base_tcp[i] · T_tcp_cam · T_cam_board[i] = T_base_board`` for every pose, with two unknown
constants: ``X = T_tcp_cam`` (camera-frame points → TCP frame, the wrist mount) and ``W = T_base_board``
(where the board lies).

* **AX = XB** (``method="park"``, Park & Martin 1994): two poses ``i, j`` give
  ``T_base_tcp[i]⁻¹ T_base_tcp[j] · X = X · T_cam_board[i] T_cam_board[j]⁻¹``, i.e. ``A X = X B`` with
  ``A = G_i⁻¹ G_j`` (the TCP's motion in its own frame) and ``B = C_i C_j⁻¹`` (the camera's motion).
  :func:`calib.handeye.solve_ax_xb` solves it; ``W`` is averaged from ``G_i X C_i`` afterwards.
* **AX = ZB** (``method="shah"``, Shah 2013): ``G_i · X = W · C_i⁻¹``, so
  :func:`calib.handeye.solve_ax_zb` on ``(A_i, B_i) = (G_i, C_i⁻¹)`` gives ``(X, W)`` at once.

Degenerate motion is refused with :class:`calib.handeye.DegenerateMotionError` naming the motion to add
(:func:`check_eye_in_hand_motion`): **pure translation** (the camera only slides: every rotation-based
method fails; "add rotations about two different axes"), too few poses, or rotations about a single axis
(the translation of ``X`` along it is unobservable; "add rotations about a second axis").

:func:`refine_eye_in_hand` then fits ``X`` and ``W`` to the detected corners (Huber, Levenberg-Marquardt).
Corner ``k`` of pose ``i`` is predicted at ``π(K, dist, X⁻¹ · G_i⁻¹ · W · P_k)``, which is the eye-to-hand
model of :mod:`calib.handeye_refine` with ``T_cam_base := X⁻¹ = T_cam_tcp``, ``T_base_gripper := G_i⁻¹``
and ``T_gripper_board := W``. The solver there is reused unchanged. The uncertainty comes from the
Jacobian at the solution: ``cov = σ̂² (JᵀWJ)⁻¹`` with ``σ̂²`` the weighted residual variance per coordinate.
It is reported as σ of ``X``'s translation (mm, TCP axes) and rotation (deg, about TCP axes). It covers
pixel noise only: FK and intrinsics errors are not in it (they show up as residual and as bias).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any, Final, Literal

import numpy as np
import numpy.typing as npt

from calib.handeye import (
    METHODS,
    DegenerateMotionError,
    MotionReport,
    _pairs,
    check_motion,
    solve_ax_xb,
    solve_ax_zb,
)
from calib.handeye_refine import refine_eye_to_hand, reprojection_residuals
from calib.rotations import as_transforms, nearest_rotation, pose_difference, rigid, rotation_angle, rotation_exp
from pilworld.geometry import invert_transform

__all__ = [
    "EyeInHandResult",
    "RefinedEyeInHand",
    "check_eye_in_hand_motion",
    "eye_in_hand_residuals",
    "refine_eye_in_hand",
    "solve_eye_in_hand",
]

FloatArray = npt.NDArray[np.float64]
Method = Literal["park", "shah"]

#: Advice appended to every refusal: what a user moves to fix it.
ADD_ROTATIONS: Final = (
    "add rotations about two different axes: tilt the wrist camera by 15-35° about two different axes (e.g. "
    "the TCP's x and y axes), keeping the board in view"
)


def check_eye_in_hand_motion(
    T_base_tcp: Sequence[npt.ArrayLike] | npt.ArrayLike,
    min_poses: int = 3,
    min_rotation_span_deg: float = 5.0,
    min_axis_spread: float = 0.1,
) -> MotionReport:
    """:func:`calib.handeye.check_motion` on the TCP motion, with messages for a wrist camera.

    The test runs on ``T_base_tcp[i]⁻¹`` so a single rotation axis is reported in the TCP frame, the frame
    the user tilts the camera in. Raises :class:`DegenerateMotionError` whose message starts with the
    cause (``pure translation``, ``too few poses``, ``rotations about a single axis``) and names the motion
    to add.
    """
    G = as_transforms(T_base_tcp, "T_base_tcp")
    n = G.shape[0]
    if n >= 2:
        span = max(math.degrees(rotation_angle(G[j, :3, :3].T @ G[i, :3, :3])) for i, j in _pairs(n))
        if span <= min_rotation_span_deg:
            moved = max(float(np.linalg.norm(G[j, :3, 3] - G[i, :3, 3])) for i, j in _pairs(n))
            raise DegenerateMotionError(
                f"pure translation: the {n} TCP poses differ by at most {span:.2f}° in orientation (need more "
                f"than {min_rotation_span_deg}°) while the TCP moves up to {moved * 1e3:.0f} mm; a sliding camera "
                f"cannot determine its mount. Pure translation: {ADD_ROTATIONS}"
            )
    try:
        return check_motion(
            invert_transform(G),
            min_poses=min_poses,
            min_rotation_span_deg=min_rotation_span_deg,
            min_axis_spread=min_axis_spread,
        )
    except DegenerateMotionError as exc:
        text = str(exc)
        if text.startswith("too few poses"):
            raise DegenerateMotionError(
                f"too few poses: got {n}, need at least {max(min_poses, 3)} wrist-camera views of the board; "
                f"record more poses and {ADD_ROTATIONS}"
            ) from None
        if text.startswith("rotations about a single axis"):
            axes = _main_axis(G)
            raise DegenerateMotionError(
                "rotations about a single axis: every relative rotation of the TCP is about "
                f"{np.round(axes, 3).tolist()} (TCP frame), so the camera's offset along that axis is unobservable; "
                "add rotations about a second axis, perpendicular to it (tilt the wrist camera sideways as well "
                f"as forwards; the relative rotation axes' spread is below min_axis_spread = {min_axis_spread})"
            ) from None
        raise DegenerateMotionError(f"{text}. For a wrist camera: {ADD_ROTATIONS}") from None


def _main_axis(G: FloatArray) -> FloatArray:
    axes = []
    for i, j in _pairs(G.shape[0]):
        R = G[i, :3, :3].T @ G[j, :3, :3]
        if math.degrees(rotation_angle(R)) >= 1.0:
            w = np.array([R[2, 1] - R[1, 2], R[0, 2] - R[2, 0], R[1, 0] - R[0, 1]])
            axes.append(w / max(float(np.linalg.norm(w)), 1e-300))
    if not axes:
        return np.zeros(3)
    A = np.asarray(axes)
    out: FloatArray = np.linalg.eigh(A.T @ A)[1][:, -1]
    return out * (1.0 if out[np.argmax(np.abs(out))] > 0 else -1.0)


@dataclass(frozen=True, eq=False)
class EyeInHandResult:
    """A closed-form eye-in-hand solution and how well it explains the input poses."""

    T_tcp_cam: FloatArray  #: camera-frame points → TCP frame (the wrist mount)
    T_base_board: FloatArray  #: board-frame points → base frame (where the board lies)
    method: str
    motion: MotionReport
    #: per pose: (translation error in metres, rotation error in degrees) of X⁻¹ G_i⁻¹ W against T_cam_board[i]
    pose_residuals: tuple[tuple[float, float], ...]

    @property
    def T_cam_tcp(self) -> FloatArray:  # noqa: N802 - the transform's name
        return invert_transform(self.T_tcp_cam)

    @property
    def residual_rms_m(self) -> float:
        return math.sqrt(float(np.mean([t**2 for t, _ in self.pose_residuals])))

    @property
    def residual_rms_deg(self) -> float:
        return math.sqrt(float(np.mean([r**2 for _, r in self.pose_residuals])))


def solve_eye_in_hand(
    T_base_tcp: Sequence[npt.ArrayLike] | npt.ArrayLike,
    T_cam_board: Sequence[npt.ArrayLike] | npt.ArrayLike,
    method: Method = "shah",
    min_rotation_span_deg: float = 5.0,
    min_axis_spread: float = 0.1,
) -> EyeInHandResult:
    """Closed-form ``T_tcp_cam`` and ``T_base_board`` for a camera on the arm and a fixed board.

    See the module docstring for the conventions. Raises :class:`DegenerateMotionError` for degenerate
    motion (naming the motion to add) and ``ValueError`` for mismatched or non-rigid inputs.
    """
    G = as_transforms(T_base_tcp, "T_base_tcp")
    C = as_transforms(T_cam_board, "T_cam_board")
    if G.shape[0] != C.shape[0]:
        raise ValueError(f"T_base_tcp and T_cam_board must pair up one to one, got {G.shape[0]} and {C.shape[0]} poses")
    if method not in METHODS:
        raise ValueError(f"method: expected one of {', '.join(METHODS)}, got {method!r}")
    motion = check_eye_in_hand_motion(G, min_rotation_span_deg=min_rotation_span_deg, min_axis_spread=min_axis_spread)
    if method == "park":
        pairs = _pairs(G.shape[0])
        A = [invert_transform(G[i]) @ G[j] for i, j in pairs]
        B = [C[i] @ invert_transform(C[j]) for i, j in pairs]
        X = solve_ax_xb(A, B)
        Ws = np.asarray([g @ X @ c for g, c in zip(G, C, strict=True)])
        W = rigid(nearest_rotation(Ws[:, :3, :3].sum(axis=0)), Ws[:, :3, 3].mean(axis=0))
    else:
        X, W = solve_ax_zb(G, invert_transform(C))
    X_inv = invert_transform(X)
    residuals = tuple(pose_difference(X_inv @ invert_transform(g) @ W, c) for g, c in zip(G, C, strict=True))
    return EyeInHandResult(T_tcp_cam=X, T_base_board=W, method=method, motion=motion, pose_residuals=residuals)


def eye_in_hand_residuals(
    T_tcp_cam: npt.ArrayLike,
    T_base_board: npt.ArrayLike,
    T_base_tcp: Sequence[npt.ArrayLike] | npt.ArrayLike,
    board_points: Sequence[npt.ArrayLike],
    image_points: Sequence[npt.ArrayLike],
    K: npt.ArrayLike,
    dist: npt.ArrayLike,
) -> FloatArray:
    """``(sum n_i, 2)`` predicted minus detected pixels of every corner of every pose."""
    G = as_transforms(T_base_tcp, "T_base_tcp")
    X = as_transforms([T_tcp_cam], "T_tcp_cam")[0]
    return reprojection_residuals(
        invert_transform(X), T_base_board, invert_transform(G), board_points, image_points, K, dist
    )


@dataclass(frozen=True, eq=False)
class RefinedEyeInHand:
    """The refined wrist mount and board pose, the pixel errors they leave and their uncertainty."""

    T_tcp_cam: FloatArray  #: camera-frame points → TCP frame
    T_base_board: FloatArray  #: board-frame points → base frame
    rms_px: float  #: plain RMS of the corner errors (not the robust cost)
    initial_rms_px: float
    per_pose_rms_px: tuple[float, ...]
    iterations: int
    converged: bool
    #: ``(12, 12)`` covariance of (ω_X, δ_X, ω_W, δ_W): rotation vectors (rad) and translations (m) of the
    #: updates ``R ← exp(ω) R``, ``t ← t + δ`` of ``T_tcp_cam`` and ``T_base_board``
    covariance: FloatArray

    @property
    def sigma_translation_mm(self) -> FloatArray:
        """σ of ``T_tcp_cam``'s translation along the TCP axes, millimetres."""
        out: FloatArray = 1e3 * np.sqrt(np.maximum(np.diag(self.covariance)[3:6], 0.0))
        return out

    @property
    def sigma_rotation_deg(self) -> FloatArray:
        """σ of ``T_tcp_cam``'s rotation about the TCP axes, degrees."""
        out: FloatArray = np.degrees(np.sqrt(np.maximum(np.diag(self.covariance)[0:3], 0.0)))
        return out

    def uncertainty(self) -> dict[str, Any]:
        """JSON-friendly σ: per axis and combined (root sum of squares), of the wrist mount ``T_tcp_cam``."""
        t, r = self.sigma_translation_mm, self.sigma_rotation_deg
        return {
            "sigma_translation_mm": float(np.linalg.norm(t)),
            "sigma_rotation_deg": float(np.linalg.norm(r)),
            "sigma_translation_mm_xyz": t.tolist(),
            "sigma_rotation_deg_xyz": r.tolist(),
            "note": "from the pixel residuals only (FK and intrinsics errors are not included)",
        }


def _update(T: FloatArray, p: FloatArray) -> FloatArray:
    return rigid(rotation_exp(p[:3]) @ T[:3, :3], T[:3, 3] + p[3:])


def _covariance(
    X: FloatArray,
    W: FloatArray,
    G: FloatArray,
    board_points: Sequence[npt.ArrayLike],
    image_points: Sequence[npt.ArrayLike],
    K: npt.ArrayLike,
    dist: npt.ArrayLike,
    huber_px: float,
) -> FloatArray:
    def residuals(p: FloatArray) -> FloatArray:
        return eye_in_hand_residuals(_update(X, p[:6]), _update(W, p[6:]), G, board_points, image_points, K, dist)

    r = residuals(np.zeros(12))
    norms = np.linalg.norm(r, axis=1)
    w = np.repeat(np.where(norms <= huber_px, 1.0, huber_px / np.maximum(norms, 1e-300)), 2)
    h = 1e-6
    J = np.empty((r.size, 12))
    for k in range(12):
        dp = np.zeros(12)
        dp[k] = h
        J[:, k] = ((residuals(dp) - residuals(-dp)) / (2.0 * h)).reshape(-1)
    dof = max(r.size - 12, 1)
    s2 = float(np.sum(w * r.reshape(-1) ** 2)) / dof
    H = J.T @ (w[:, None] * J)
    cov: FloatArray = s2 * np.asarray(np.linalg.pinv(H), dtype=np.float64)
    return cov


def refine_eye_in_hand(
    T_tcp_cam: npt.ArrayLike,
    T_base_board: npt.ArrayLike,
    T_base_tcp: Sequence[npt.ArrayLike] | npt.ArrayLike,
    board_points: Sequence[npt.ArrayLike],
    image_points: Sequence[npt.ArrayLike],
    K: npt.ArrayLike,
    dist: npt.ArrayLike,
    huber_px: float = 1.0,
    max_iterations: int = 50,
) -> RefinedEyeInHand:
    """Refine an initial ``T_tcp_cam``, ``T_base_board`` (e.g. from :func:`solve_eye_in_hand`) on the pixels.

    ``board_points[i]`` ``(n_i, 3)`` (board frame, metres) and ``image_points[i]`` ``(n_i, 2)`` (pixels) are
    the corners detected at pose ``i``; ``K``, ``dist`` the camera's intrinsics.
    """
    G = as_transforms(T_base_tcp, "T_base_tcp")
    X0 = as_transforms([T_tcp_cam], "T_tcp_cam")[0]
    refined = refine_eye_to_hand(
        invert_transform(X0),
        T_base_board,
        invert_transform(G),
        board_points,
        image_points,
        K,
        dist,
        huber_px=huber_px,
        max_iterations=max_iterations,
    )
    X = invert_transform(refined.T_cam_base)
    W = refined.T_gripper_board
    return RefinedEyeInHand(
        T_tcp_cam=X,
        T_base_board=W,
        rms_px=refined.rms_px,
        initial_rms_px=refined.initial_rms_px,
        per_pose_rms_px=refined.per_pose_rms_px,
        iterations=refined.iterations,
        converged=refined.converged,
        covariance=_covariance(X, W, G, board_points, image_points, K, dist, huber_px),
    )
