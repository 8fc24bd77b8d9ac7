"""Small SO(3)/SE(3) helpers for the calibration solvers (float64, one pose at a time or stacked)."""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import cast

import numpy as np
import numpy.typing as npt

from pilworld.geometry import as_finite_array, is_rigid_transform

__all__ = [
    "as_transforms",
    "nearest_rotation",
    "pose_difference",
    "rigid",
    "rotation_angle",
    "rotation_exp",
    "rotation_log",
]

FloatArray = npt.NDArray[np.float64]


def rotation_exp(w: npt.ArrayLike) -> FloatArray:
    """Rotation matrix of the rotation vector ``w`` (axis times angle in radians), Rodrigues' formula."""
    v = np.asarray(w, dtype=np.float64).reshape(3)
    theta = float(np.linalg.norm(v))
    W = np.array([[0.0, -v[2], v[1]], [v[2], 0.0, -v[0]], [-v[1], v[0], 0.0]])
    if theta < 1e-8:  # second-order Taylor expansion: exact to float precision here
        R: FloatArray = np.eye(3) + W + 0.5 * W @ W
    else:
        R = np.eye(3) + math.sin(theta) / theta * W + (1.0 - math.cos(theta)) / theta**2 * W @ W
    return R


def rotation_angle(R: npt.ArrayLike) -> float:
    """Rotation angle of ``R`` in radians, in [0, π]; robust near 0 (uses the skew part, not only the trace)."""
    m = np.asarray(R, dtype=np.float64)
    s = 0.5 * float(np.linalg.norm([m[2, 1] - m[1, 2], m[0, 2] - m[2, 0], m[1, 0] - m[0, 1]]))
    c = 0.5 * (float(np.trace(m)) - 1.0)
    return math.atan2(s, c)


def rotation_log(R: npt.ArrayLike) -> FloatArray:
    """Rotation vector (axis times angle, radians) of the rotation matrix ``R``; the inverse of rotation_exp."""
    m = np.asarray(R, dtype=np.float64)
    theta = rotation_angle(m)
    skew = np.array([m[2, 1] - m[1, 2], m[0, 2] - m[2, 0], m[1, 0] - m[0, 1]])
    if theta < 1e-8:
        return 0.5 * skew
    if theta < math.pi - 1e-4:
        return theta / (2.0 * math.sin(theta)) * skew
    # Near π the skew part vanishes. The symmetric part is cos θ I + (1 - cos θ) a aᵀ, so a aᵀ follows
    # exactly (no skew term leaks in); its dominant column gives the axis, the skew part its sign.
    B = (0.5 * (m + m.T) - math.cos(theta) * np.eye(3)) / (1.0 - math.cos(theta))
    k = int(np.argmax(np.diag(B)))
    axis = B[:, k] / math.sqrt(max(B[k, k], 1e-300))
    if float(axis @ skew) < 0.0:
        axis = -axis
    return theta * axis / np.linalg.norm(axis)


def nearest_rotation(M: npt.ArrayLike) -> FloatArray:
    """The rotation closest to ``M`` in the Frobenius norm (SVD projection onto SO(3), never a reflection)."""
    U, _, Vt = np.linalg.svd(np.asarray(M, dtype=np.float64))
    D = np.diag([1.0, 1.0, float(np.sign(np.linalg.det(U @ Vt))) or 1.0])
    R: FloatArray = U @ D @ Vt
    return R


def rigid(R: npt.ArrayLike, t: npt.ArrayLike) -> FloatArray:
    """The 4x4 transform ``[[R, t], [0, 1]]``."""
    T = np.eye(4)
    T[:3, :3] = np.asarray(R, dtype=np.float64)
    T[:3, 3] = np.asarray(t, dtype=np.float64).reshape(3)
    return T


def pose_difference(T_a: npt.ArrayLike, T_b: npt.ArrayLike) -> tuple[float, float]:
    """(translation difference in metres, rotation angle of ``R_a R_bᵀ`` in degrees) of two 4x4 poses."""
    a, b = np.asarray(T_a, dtype=np.float64), np.asarray(T_b, dtype=np.float64)
    return float(np.linalg.norm(a[:3, 3] - b[:3, 3])), math.degrees(rotation_angle(a[:3, :3] @ b[:3, :3].T))


def as_transforms(poses: Sequence[npt.ArrayLike] | npt.ArrayLike, name: str) -> FloatArray:
    """``(N, 4, 4)`` float64 rigid transforms; ``ValueError`` naming ``name`` and the first non-rigid index."""
    arr = as_finite_array(cast(npt.ArrayLike, poses), name, (4, 4))
    if arr.ndim != 3:
        raise ValueError(f"{name}: expected a list of 4x4 transforms (shape (N, 4, 4)), got shape {arr.shape}")
    for i, T in enumerate(arr):
        if not is_rigid_transform(T, atol=1e-5):
            raise ValueError(
                f"{name}[{i}] is not a rigid transform (R orthonormal, det +1, last row 0 0 0 1): {T.tolist()}"
            )
    return arr
