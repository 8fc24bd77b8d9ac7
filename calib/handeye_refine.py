"""Refine a hand-eye solution of either mount on the pixel reprojection error (Huber Levenberg-Marquardt).

The closed forms of :mod:`calib.handeye_solve` minimise algebraic pose errors, which weight a far, steep
board pose (poorly measured by solvePnP) like a close, frontal one. Here the camera transform and the board
pose are fitted directly to the detected corners. The pixel model is the fixed camera's: corner ``k`` of
pose ``i`` is predicted at ``π(K, dist, T_cam_base · T_base_gripper[i] · T_gripper_board · P_k)``; a wrist
camera is the same model with ``T_cam_base := T_tcp_cam⁻¹``, ``T_base_gripper := G_i⁻¹`` and
``T_gripper_board := T_base_board`` (:meth:`calib.handeye_mount.CameraMount.fixed_camera`), so
:func:`refine_hand_eye` runs one solver (:func:`calib.rigid_lm.levenberg_marquardt`, 12 parameters: cheap)
for both mounts. Forward kinematics is taken as exact (its error shows up as residual).

For a wrist camera the result also carries its uncertainty, from the Jacobian at the solution in the
mount's own parameters: ``cov = σ̂² (JᵀWJ)⁻¹`` with ``σ̂²`` the weighted residual variance per coordinate,
reported as σ of ``T_tcp_cam``'s translation (mm, TCP axes) and rotation (deg, about TCP axes). It covers
pixel noise only: FK and intrinsics errors are not in it (they show up as residual and as bias).
:func:`refine_shared_camera` fits one fixed camera to several boards (one per arm) with the same solver.
See docs/calibration.md, "3. Hand-eye".
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any, Final

import numpy as np
import numpy.typing as npt

from calib.distortion import DistortionModel
from calib.handeye_mount import CameraMount, TransformName
from calib.rigid_lm import huber, levenberg_marquardt, numeric_jacobian, update_transforms
from calib.rotations import as_transforms

__all__ = [
    "HandEyeRefinement",
    "RefinedEyeInHand",
    "RefinedHandEye",
    "eye_in_hand_residuals",
    "hand_eye_residuals",
    "refine_eye_in_hand",
    "refine_eye_to_hand",
    "refine_hand_eye",
    "refine_shared_camera",
    "reprojection_residuals",
]

FloatArray = npt.NDArray[np.float64]
Poses = Sequence[npt.ArrayLike] | npt.ArrayLike
Points = Sequence[npt.ArrayLike]


@dataclass(frozen=True, eq=False)
class HandEyeRefinement:
    """The refined transforms of either mount and the pixel errors they leave."""

    X: FloatArray  #: the camera transform the mount solves for (:attr:`CameraMount.solved`)
    Y: FloatArray  #: the board pose (:attr:`CameraMount.board_pose`)
    rms_px: float  #: plain RMS of the corner errors (not the robust cost)
    initial_rms_px: float
    per_pose_rms_px: tuple[float, ...]
    iterations: int
    converged: bool


class RefinedHandEye(HandEyeRefinement):
    """The refined eye-to-hand transforms."""

    T_cam_base = TransformName("X", "Maps base-frame points into the camera frame.")
    T_gripper_board = TransformName("Y", "Maps board-frame points into the gripper frame.")


@dataclass(frozen=True, eq=False)
class RefinedEyeInHand(HandEyeRefinement):
    """The refined wrist mount and board pose, the pixel errors they leave and their uncertainty."""

    #: ``(12, 12)`` covariance of (ω_X, δ_X, ω_W, δ_W): rotation vectors (rad) and translations (m) of the
    #: updates ``R ← exp(ω) R``, ``t ← t + δ`` of ``T_tcp_cam`` and ``T_base_board``
    covariance: FloatArray

    T_tcp_cam = TransformName("X", "Camera-frame points → TCP frame.")
    T_base_board = TransformName("Y", "Board-frame points → base frame.")

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


class _Problem:
    def __init__(
        self,
        G: FloatArray,
        board_points: Sequence[npt.ArrayLike],
        image_points: Sequence[npt.ArrayLike],
        K: npt.ArrayLike,
        dist: npt.ArrayLike,
    ) -> None:
        if len(board_points) != G.shape[0] or len(image_points) != G.shape[0]:
            raise ValueError(
                f"need one set of board and image points per pose: {G.shape[0]} poses, {len(board_points)} board "
                f"point sets, {len(image_points)} image point sets"
            )
        objs = [np.asarray(p, dtype=np.float64).reshape(-1, 3) for p in board_points]
        imgs = [np.asarray(p, dtype=np.float64).reshape(-1, 2) for p in image_points]
        for i, (o, m) in enumerate(zip(objs, imgs, strict=True)):
            if o.shape[0] != m.shape[0]:
                raise ValueError(f"pose {i}: {o.shape[0]} board points but {m.shape[0]} image points")
        self.G = G
        self.obj = np.concatenate(objs)
        self.uv = np.concatenate(imgs)
        self.pose = np.repeat(np.arange(G.shape[0]), [o.shape[0] for o in objs])
        if self.obj.shape[0] < 6:
            raise ValueError(f"refinement needs at least 6 corners in total, got {self.obj.shape[0]}")
        self.K = np.asarray(K, dtype=np.float64)
        self.distortion = DistortionModel(dist)

    def residuals(self, X: FloatArray, Y: FloatArray) -> FloatArray:
        M = X @ self.G @ Y  # (N, 4, 4): board -> camera for each pose
        Mp = M[self.pose]
        pc = np.einsum("nij,nj->ni", Mp[:, :3, :3], self.obj) + Mp[:, :3, 3]
        z = np.maximum(pc[:, 2], 1e-9)  # a board behind the camera is a wrong start, not a crash
        xd, yd, _ = self.distortion.distort_xy(pc[:, 0] / z, pc[:, 1] / z)
        u = self.K[0, 0] * xd + self.K[0, 1] * yd + self.K[0, 2]
        v = self.K[1, 1] * yd + self.K[1, 2]
        out: FloatArray = np.stack([u, v], axis=-1) - self.uv
        return out


def reprojection_residuals(
    T_cam_base: npt.ArrayLike,
    T_gripper_board: npt.ArrayLike,
    T_base_gripper: Poses,
    board_points: Points,
    image_points: Points,
    K: npt.ArrayLike,
    dist: npt.ArrayLike,
) -> FloatArray:
    """``(sum n_i, 2)`` predicted minus detected pixels of every corner of every pose (a fixed camera)."""
    problem = _Problem(as_transforms(T_base_gripper, "T_base_gripper"), board_points, image_points, K, dist)
    X = as_transforms([T_cam_base], "T_cam_base")[0]
    Y = as_transforms([T_gripper_board], "T_gripper_board")[0]
    return problem.residuals(X, Y)


def hand_eye_residuals(
    mount: CameraMount,
    X: npt.ArrayLike,
    Y: npt.ArrayLike,
    T_base_gripper: Poses,
    board_points: Points,
    image_points: Points,
    K: npt.ArrayLike,
    dist: npt.ArrayLike,
) -> FloatArray:
    """``(sum n_i, 2)`` predicted minus detected pixels for ``mount``'s camera transform ``X`` and board pose ``Y``."""
    G = as_transforms(T_base_gripper, mount.fk)
    X_fixed = mount.fixed_camera(as_transforms([X], mount.solved)[0])
    return reprojection_residuals(X_fixed, Y, mount.fixed_camera(G), board_points, image_points, K, dist)


def eye_in_hand_residuals(
    T_tcp_cam: npt.ArrayLike,
    T_base_board: npt.ArrayLike,
    T_base_tcp: Poses,
    board_points: Points,
    image_points: Points,
    K: npt.ArrayLike,
    dist: npt.ArrayLike,
) -> FloatArray:
    """:func:`hand_eye_residuals` of a wrist camera."""
    mount: Final = CameraMount.EYE_IN_HAND
    return hand_eye_residuals(mount, T_tcp_cam, T_base_board, T_base_tcp, board_points, image_points, K, dist)


def refine_eye_to_hand(
    T_cam_base: npt.ArrayLike,
    T_gripper_board: npt.ArrayLike,
    T_base_gripper: Poses,
    board_points: Points,
    image_points: Points,
    K: npt.ArrayLike,
    dist: npt.ArrayLike,
    huber_px: float = 1.0,
    max_iterations: int = 50,
) -> RefinedHandEye:
    """Refine an initial ``T_cam_base``, ``T_gripper_board`` (e.g. from :func:`calib.handeye_solve.solve_eye_to_hand`).

    ``board_points[i]`` ``(n_i, 3)`` (board frame, metres) and ``image_points[i]`` ``(n_i, 2)`` (pixels) are
    the corners detected at pose ``i``; ``K``, ``dist`` the camera's intrinsics.
    """
    if not (math.isfinite(huber_px) and huber_px > 0.0):
        raise ValueError(f"huber_px must be a positive number of pixels, got {huber_px!r}")
    problem = _Problem(as_transforms(T_base_gripper, "T_base_gripper"), board_points, image_points, K, dist)
    X = as_transforms([T_cam_base], "T_cam_base")[0]
    Y = as_transforms([T_gripper_board], "T_gripper_board")[0]
    fit = levenberg_marquardt(lambda Ts: problem.residuals(Ts[0], Ts[1]), [X, Y], huber_px, max_iterations)
    sq = (fit.residuals**2).sum(axis=1)
    per_pose = tuple(
        math.sqrt(float(sq[problem.pose == i].mean())) if np.any(problem.pose == i) else math.nan
        for i in range(problem.G.shape[0])
    )
    initial_rms = math.sqrt(float((fit.initial_residuals**2).sum(axis=1).mean()))
    X, Y = fit.transforms
    return RefinedHandEye(
        X=X,
        Y=Y,
        rms_px=fit.rms_px,
        initial_rms_px=initial_rms,
        per_pose_rms_px=per_pose,
        iterations=fit.iterations,
        converged=fit.converged,
    )


def _covariance(
    mount: CameraMount,
    X: FloatArray,
    Y: FloatArray,
    G: FloatArray,
    board_points: Points,
    image_points: Points,
    K: npt.ArrayLike,
    dist: npt.ArrayLike,
    huber_px: float,
) -> FloatArray:
    """``(12, 12)`` covariance of ``mount``'s (``X``, ``Y``) updates from the Jacobian at the solution."""

    def residuals(p: FloatArray) -> FloatArray:
        X_p, Y_p = update_transforms([X, Y], p)
        return hand_eye_residuals(mount, X_p, Y_p, G, board_points, image_points, K, dist)

    r = residuals(np.zeros(12))
    w = np.repeat(huber(np.linalg.norm(r, axis=1), huber_px)[1], 2)
    J = numeric_jacobian(residuals, r.size, 12)
    dof = max(r.size - 12, 1)
    s2 = float(np.sum(w * r.reshape(-1) ** 2)) / dof
    H = J.T @ (w[:, None] * J)
    cov: FloatArray = s2 * np.asarray(np.linalg.pinv(H), dtype=np.float64)
    return cov


def refine_eye_in_hand(
    T_tcp_cam: npt.ArrayLike,
    T_base_board: npt.ArrayLike,
    T_base_tcp: Poses,
    board_points: Points,
    image_points: Points,
    K: npt.ArrayLike,
    dist: npt.ArrayLike,
    huber_px: float = 1.0,
    max_iterations: int = 50,
) -> RefinedEyeInHand:
    """Refine an initial ``T_tcp_cam``, ``T_base_board`` (e.g. from :func:`calib.handeye_solve.solve_eye_in_hand`).

    The eye-to-hand refinement on the equivalent fixed camera (module docstring), plus the uncertainty.
    """
    mount = CameraMount.EYE_IN_HAND
    G = as_transforms(T_base_tcp, "T_base_tcp")
    X0_fixed = mount.fixed_camera(as_transforms([T_tcp_cam], "T_tcp_cam")[0])
    fixed = refine_eye_to_hand(
        X0_fixed, T_base_board, mount.fixed_camera(G), board_points, image_points, K, dist, huber_px, max_iterations
    )
    X, W = mount.fixed_camera(fixed.X), fixed.Y
    return RefinedEyeInHand(
        X=X,
        Y=W,
        rms_px=fixed.rms_px,
        initial_rms_px=fixed.initial_rms_px,
        per_pose_rms_px=fixed.per_pose_rms_px,
        iterations=fixed.iterations,
        converged=fixed.converged,
        covariance=_covariance(mount, X, W, G, board_points, image_points, K, dist, huber_px),
    )


_REFINERS: Final[dict[CameraMount, Callable[..., HandEyeRefinement]]] = {
    CameraMount.EYE_TO_HAND: refine_eye_to_hand,
    CameraMount.EYE_IN_HAND: refine_eye_in_hand,
}


def refine_hand_eye(
    mount: CameraMount,
    X: npt.ArrayLike,
    Y: npt.ArrayLike,
    T_base_gripper: Poses,
    board_points: Points,
    image_points: Points,
    K: npt.ArrayLike,
    dist: npt.ArrayLike,
    huber_px: float = 1.0,
) -> HandEyeRefinement:
    """Refine ``mount``'s closed-form ``X``, ``Y`` (:func:`calib.handeye_solve.solve_hand_eye`) on the pixels."""
    return _REFINERS[mount](X, Y, T_base_gripper, board_points, image_points, K, dist, huber_px=huber_px)


def refine_shared_camera(
    T_cam_base: npt.ArrayLike,
    boards: Sequence[tuple[npt.ArrayLike, Poses, Points, Points]],
    K: npt.ArrayLike,
    dist: npt.ArrayLike,
    *,
    huber_px: float = 1.0,
    max_iterations: int = 50,
) -> tuple[FloatArray, list[FloatArray], float]:
    """One fixed camera's ``T_cam_base`` and one ``T_gripper_board`` per board fitted to all their corners.

    ``boards[k]`` is (initial ``T_gripper_board``, ``T_base_gripper`` per pose, board points, image points)
    of one arm's views: the model of :func:`refine_eye_to_hand` with 6 + 6·boards parameters. It stops only
    when the cost stops decreasing. Returns the transforms and the plain RMS of the corner errors.
    """
    problems = [_Problem(as_transforms(G, "T_base_gripper"), objs, imgs, K, dist) for _, G, objs, imgs in boards]
    start = [np.asarray(T_cam_base, dtype=np.float64), *(np.asarray(b[0], dtype=np.float64) for b in boards)]

    def residuals(Ts: list[FloatArray]) -> FloatArray:
        return np.concatenate([p.residuals(Ts[0], Y) for p, Y in zip(problems, Ts[1:], strict=True)])

    fit = levenberg_marquardt(residuals, start, huber_px, max_iterations, stop_on_small_step=False)
    return fit.transforms[0], fit.transforms[1:], fit.rms_px
