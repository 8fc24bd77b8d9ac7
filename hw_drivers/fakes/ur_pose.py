"""UR pose vectors ``[x, y, z, rx, ry, rz]`` (position [m] + rotation vector [rad]) <-> 4x4 transforms.

URScript and ur_rtde carry every Cartesian pose as a rotation vector (axis * angle), so the fake controller
converts at its boundary and computes with :mod:`pilworld.kinematics` transforms inside.
"""

from __future__ import annotations

import numpy as np
import numpy.typing as npt

FloatArray = npt.NDArray[np.float64]


def _skew(v: FloatArray) -> FloatArray:
    return np.array([[0.0, -v[2], v[1]], [v[2], 0.0, -v[0]], [-v[1], v[0], 0.0]])


def rotvec_to_matrix(rv: npt.ArrayLike) -> FloatArray:
    """Rodrigues' formula: the rotation matrix of rotation vector ``rv`` (3,)."""
    v = np.asarray(rv, dtype=np.float64)
    angle = float(np.linalg.norm(v))
    if angle < 1e-12:
        return np.eye(3) + _skew(v)
    k = _skew(v / angle)
    R: FloatArray = np.eye(3) + np.sin(angle) * k + (1.0 - np.cos(angle)) * (k @ k)
    return R


def matrix_to_rotvec(R: npt.ArrayLike) -> FloatArray:
    """The rotation vector (3,) of rotation matrix ``R``, angle in [0, pi]."""
    m = np.asarray(R, dtype=np.float64)
    axis_sin = np.array([m[2, 1] - m[1, 2], m[0, 2] - m[2, 0], m[1, 0] - m[0, 1]]) / 2.0
    # atan2 of (sin, cos) keeps full precision near 0 and pi, where arccos(cos) loses half the digits
    angle = float(np.arctan2(np.linalg.norm(axis_sin), (np.trace(m) - 1.0) / 2.0))
    if angle < 1e-6:
        return axis_sin  # sin(angle) ~ angle
    if np.pi - angle > 1e-4:
        scaled: FloatArray = axis_sin * (angle / np.sin(angle))
        return scaled
    # near pi the antisymmetric part vanishes: take the axis from the symmetric part,
    # (R + R^T) / 2 = cos(angle) I + (1 - cos(angle)) k k^T
    cos = np.cos(angle)
    sym = ((m + m.T) / 2.0 - cos * np.eye(3)) / (1.0 - cos)
    i = int(np.argmax(np.diag(sym)))
    axis = sym[:, i] / np.sqrt(max(sym[i, i], 1e-300))
    if np.dot(axis_sin, axis) < 0:
        axis = -axis
    rv: FloatArray = axis * angle
    return rv


def pose_to_matrix(pose: npt.ArrayLike) -> FloatArray:
    """``[x, y, z, rx, ry, rz]`` -> the 4x4 transform."""
    p = np.asarray(pose, dtype=np.float64)
    if p.shape != (6,) or not np.all(np.isfinite(p)):
        raise ValueError(f"pose: expected 6 finite values [x, y, z, rx, ry, rz], got {p!r}")
    T = np.eye(4)
    T[:3, :3] = rotvec_to_matrix(p[3:])
    T[:3, 3] = p[:3]
    return T


def matrix_to_pose(T: npt.ArrayLike) -> FloatArray:
    """The 4x4 transform -> ``[x, y, z, rx, ry, rz]``."""
    m = np.asarray(T, dtype=np.float64)
    return np.concatenate([m[:3, 3], matrix_to_rotvec(m[:3, :3])])


def interpolate(T0: FloatArray, T1: FloatArray, s: float) -> FloatArray:
    """The pose a fraction ``s`` of the way from ``T0`` to ``T1``: straight line in position, slerp in rotation."""
    T = np.eye(4)
    T[:3, 3] = T0[:3, 3] + s * (T1[:3, 3] - T0[:3, 3])
    T[:3, :3] = T0[:3, :3] @ rotvec_to_matrix(s * matrix_to_rotvec(T0[:3, :3].T @ T1[:3, :3]))
    return T
