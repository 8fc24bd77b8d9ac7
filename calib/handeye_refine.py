"""Refine an eye-to-hand solution on pixel reprojection error with a robust (Huber) Levenberg-Marquardt.

The closed forms of :mod:`calib.handeye` minimise algebraic pose errors, which weight a far, steep board
pose (poorly measured by solvePnP) like a close, frontal one. Here the unknowns ``T_cam_base`` and
``T_gripper_board`` are fitted directly to the detected corners: corner ``k`` of pose ``i`` is predicted
at ``π(K, dist, T_cam_base · T_base_gripper[i] · T_gripper_board · P_k)``. Forward kinematics is taken as
exact (its error shows up as residual). Huber weights (quadratic below ``huber_px``, linear above) keep a
few bad corners from pulling the solution; scipy is not a dependency, so the solver is a small
iteratively-reweighted LM with a central-difference Jacobian (12 parameters: cheap).

Parametrisation: ``R ← exp(ω) R``, ``t ← t + δ`` for each transform, re-linearised after every accepted
step so the rotation update stays small.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from calib.distortion import DistortionModel
from calib.rotations import as_transforms, rigid, rotation_exp

__all__ = ["RefinedHandEye", "refine_eye_to_hand", "reprojection_residuals"]

FloatArray = npt.NDArray[np.float64]


@dataclass(frozen=True, eq=False)
class RefinedHandEye:
    """The refined transforms and the pixel errors they leave."""

    T_cam_base: FloatArray  #: maps base-frame points into the camera frame
    T_gripper_board: FloatArray  #: maps board-frame points into the gripper frame
    rms_px: float  #: plain RMS of the corner errors (not the robust cost)
    initial_rms_px: float
    per_pose_rms_px: tuple[float, ...]
    iterations: int
    converged: bool


def _apply(T: FloatArray, p: npt.ArrayLike) -> FloatArray:
    v = np.asarray(p, dtype=np.float64)
    return rigid(rotation_exp(v[:3]) @ T[:3, :3], T[:3, 3] + v[3:])


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
    T_base_gripper: Sequence[npt.ArrayLike] | npt.ArrayLike,
    board_points: Sequence[npt.ArrayLike],
    image_points: Sequence[npt.ArrayLike],
    K: npt.ArrayLike,
    dist: npt.ArrayLike,
) -> FloatArray:
    """``(sum n_i, 2)`` predicted minus detected pixels of every corner of every pose."""
    problem = _Problem(as_transforms(T_base_gripper, "T_base_gripper"), board_points, image_points, K, dist)
    X = as_transforms([T_cam_base], "T_cam_base")[0]
    Y = as_transforms([T_gripper_board], "T_gripper_board")[0]
    return problem.residuals(X, Y)


def _huber(norms: FloatArray, delta: float) -> tuple[float, FloatArray]:
    """Huber cost of the corner error norms and the IRLS weight of each corner."""
    quad = norms <= delta
    cost = float(np.where(quad, 0.5 * norms**2, delta * (norms - 0.5 * delta)).sum())
    weights = np.where(quad, 1.0, delta / np.maximum(norms, 1e-300))
    return cost, weights


def refine_eye_to_hand(
    T_cam_base: npt.ArrayLike,
    T_gripper_board: npt.ArrayLike,
    T_base_gripper: Sequence[npt.ArrayLike] | npt.ArrayLike,
    board_points: Sequence[npt.ArrayLike],
    image_points: Sequence[npt.ArrayLike],
    K: npt.ArrayLike,
    dist: npt.ArrayLike,
    huber_px: float = 1.0,
    max_iterations: int = 50,
) -> RefinedHandEye:
    """Refine an initial ``T_cam_base``, ``T_gripper_board`` (e.g. from :func:`calib.handeye.solve_eye_to_hand`).

    ``board_points[i]`` ``(n_i, 3)`` (board frame, metres) and ``image_points[i]`` ``(n_i, 2)`` (pixels) are
    the corners detected at pose ``i``; ``K``, ``dist`` the camera's intrinsics.
    """
    if not (math.isfinite(huber_px) and huber_px > 0.0):
        raise ValueError(f"huber_px must be a positive number of pixels, got {huber_px!r}")
    problem = _Problem(as_transforms(T_base_gripper, "T_base_gripper"), board_points, image_points, K, dist)
    X = as_transforms([T_cam_base], "T_cam_base")[0]
    Y = as_transforms([T_gripper_board], "T_gripper_board")[0]

    def evaluate(X: FloatArray, Y: FloatArray) -> tuple[FloatArray, float, FloatArray]:
        r = problem.residuals(X, Y)
        cost, w = _huber(np.linalg.norm(r, axis=1), huber_px)
        return r, cost, w

    r, cost, w = evaluate(X, Y)
    initial_rms = math.sqrt(float((r**2).sum(axis=1).mean()))
    lam, converged, it = 1e-3, False, 0
    h = 1e-6  # radians / metres: central differences are then accurate to ~1e-10 of the pixel Jacobian
    for it in range(1, max_iterations + 1):  # noqa: B007 - `it` is reported
        J = np.empty((r.size, 12))
        for k in range(12):
            dp = np.zeros(12)
            dp[k] = h
            rp = problem.residuals(_apply(X, dp[:6]), _apply(Y, dp[6:]))
            rm = problem.residuals(_apply(X, -dp[:6]), _apply(Y, -dp[6:]))
            J[:, k] = ((rp - rm) / (2.0 * h)).reshape(-1)
        wr = np.repeat(w, 2)
        H = J.T @ (wr[:, None] * J)
        g = J.T @ (wr * r.reshape(-1))
        improved, decrease = False, 0.0
        while lam < 1e12:
            step = np.linalg.solve(H + lam * np.diag(np.diag(H) + 1e-12), -g)
            X_new, Y_new = _apply(X, step[:6]), _apply(Y, step[6:])
            r_new, cost_new, w_new = evaluate(X_new, Y_new)
            if cost_new < cost:
                improved = True
                decrease = (cost - cost_new) / max(cost, 1e-300)
                X, Y, r, cost, w = X_new, Y_new, r_new, cost_new, w_new
                lam = max(lam / 10.0, 1e-12)
                break
            lam *= 10.0
        if not improved or decrease < 1e-12 or float(np.abs(step).max()) < 1e-12:
            converged = True
            break
    sq = (r**2).sum(axis=1)
    per_pose = tuple(
        math.sqrt(float(sq[problem.pose == i].mean())) if np.any(problem.pose == i) else math.nan
        for i in range(problem.G.shape[0])
    )
    return RefinedHandEye(
        T_cam_base=X,
        T_gripper_board=Y,
        rms_px=math.sqrt(float(sq.mean())),
        initial_rms_px=initial_rms,
        per_pose_rms_px=per_pose,
        iterations=it,
        converged=converged,
    )
