"""Rigid-transform helpers (float64 numpy, batched).

Conventions used throughout PiL-World:

* A homogeneous transform ``T_a_b`` has shape ``(..., 4, 4)`` and maps points expressed in frame ``b``
  into frame ``a``: ``p_a = T_a_b @ p_b``. Leading dimensions are batch dimensions and broadcast with
  the usual numpy rules.
* Roll/pitch/yaw follow ROS/URDF: ``R = Rz(yaw) @ Ry(pitch) @ Rx(roll)`` (extrinsic X-Y-Z, i.e. roll
  about the fixed x axis first), angles in radians, stored as ``(..., 3) = (roll, pitch, yaw)``.
* Everything is computed in float64 whatever the input dtype, because calibration and kinematics
  chains accumulate error and float32 would cost ~1e-7 relative accuracy per product.

Invalid input (wrong shape, NaN/inf) raises ``ValueError`` naming the argument, what was received and
what is allowed, so that bad data from a driver or a config file fails loudly at the boundary.
"""

from __future__ import annotations

import numpy as np
import numpy.typing as npt

__all__ = [
    "FloatArray",
    "invert_transform",
    "is_rigid_transform",
    "matrix_to_pose",
    "matrix_to_rpy",
    "pose_to_matrix",
    "rot_x",
    "rot_y",
    "rot_z",
    "rpy_to_matrix",
    "transform_points",
]

FloatArray = npt.NDArray[np.float64]

# Below this value of cos(pitch) the roll and yaw axes are treated as aligned (gimbal lock). Only
# roll + yaw (or yaw - roll) is then observable; we pick roll = 0 so the result is deterministic.
# 1e-9 keeps the regular formula (and thus continuity) everywhere it is numerically meaningful.
_GIMBAL_EPS = 1e-9


def as_finite_array(value: npt.ArrayLike, name: str, trailing: tuple[int, ...] = ()) -> FloatArray:
    """``value`` as float64 with shape ``(..., *trailing)`` and only finite entries.

    The one input check of the geometry code (poses, joint vectors, points): errors name ``name``,
    the bad shape or the first bad entry and its index.
    """
    try:
        arr = np.asarray(value, dtype=np.float64)
    except (TypeError, ValueError) as exc:
        raise ValueError(f"{name} must be a real-valued array-like; got {type(value).__name__}") from exc
    n = len(trailing)
    if arr.ndim < n or arr.shape[arr.ndim - n :] != trailing:
        allowed = "(..., " + ", ".join(str(t) for t in trailing) + ")"
        raise ValueError(f"{name} must have shape {allowed}; got shape {arr.shape}")
    if not np.all(np.isfinite(arr)):
        bad = tuple(int(i) for i in np.argwhere(~np.isfinite(arr))[0])
        raise ValueError(
            f"{name} must contain only finite values; got {float(arr[bad])} at index {bad} "
            f"(shape {arr.shape}); NaN and inf are not allowed"
        )
    return arr


def _as_vectors(value: npt.ArrayLike, name: str, size: int = 3) -> FloatArray:
    return as_finite_array(value, name, (size,))


def _as_matrices(value: npt.ArrayLike, name: str, size: int) -> FloatArray:
    return as_finite_array(value, name, (size, size))


def _axis_rotation(angle: npt.ArrayLike, axis: int, name: str) -> FloatArray:
    """Rotation by ``angle`` about coordinate ``axis`` (0=x, 1=y, 2=z); shape ``angle.shape + (3, 3)``."""
    a = as_finite_array(angle, name)
    c, s = np.cos(a), np.sin(a)
    out = np.zeros((*a.shape, 3, 3), dtype=np.float64)
    # (axis, i, j) in cyclic order x->y->z keeps the rotation right-handed: about y the plane is z->x.
    i, j = (axis + 1) % 3, (axis + 2) % 3
    out[..., axis, axis] = 1.0
    out[..., i, i] = c
    out[..., j, j] = c
    out[..., i, j] = -s
    out[..., j, i] = s
    return out


def rot_x(a: npt.ArrayLike) -> FloatArray:
    """Rotation matrices about x for angles ``a`` (radians, any shape) -> ``a.shape + (3, 3)``."""
    return _axis_rotation(a, 0, "a")


def rot_y(a: npt.ArrayLike) -> FloatArray:
    """Rotation matrices about y for angles ``a`` (radians, any shape) -> ``a.shape + (3, 3)``."""
    return _axis_rotation(a, 1, "a")


def rot_z(a: npt.ArrayLike) -> FloatArray:
    """Rotation matrices about z for angles ``a`` (radians, any shape) -> ``a.shape + (3, 3)``."""
    return _axis_rotation(a, 2, "a")


def rpy_to_matrix(rpy: npt.ArrayLike) -> FloatArray:
    """Roll/pitch/yaw ``(..., 3)`` -> rotation matrices ``(..., 3, 3)``, ``R = Rz(y) @ Ry(p) @ Rx(r)``."""
    v = _as_vectors(rpy, "rpy")
    cr, cp, cy = np.cos(v[..., 0]), np.cos(v[..., 1]), np.cos(v[..., 2])
    sr, sp, sy = np.sin(v[..., 0]), np.sin(v[..., 1]), np.sin(v[..., 2])
    # Closed form of the product, written out so a batch costs a handful of vectorised ops.
    out = np.empty((*v.shape[:-1], 3, 3), dtype=np.float64)
    out[..., 0, 0] = cy * cp
    out[..., 0, 1] = cy * sp * sr - sy * cr
    out[..., 0, 2] = cy * sp * cr + sy * sr
    out[..., 1, 0] = sy * cp
    out[..., 1, 1] = sy * sp * sr + cy * cr
    out[..., 1, 2] = sy * sp * cr - cy * sr
    out[..., 2, 0] = -sp
    out[..., 2, 1] = cp * sr
    out[..., 2, 2] = cp * cr
    return out


def matrix_to_rpy(R: npt.ArrayLike) -> FloatArray:
    """Rotation matrices ``(..., 3, 3)`` -> roll/pitch/yaw ``(..., 3)``, inverse of :func:`rpy_to_matrix`.

    Returns pitch in ``[-pi/2, pi/2]`` and roll, yaw in ``(-pi, pi]``. At gimbal lock (``|pitch| = pi/2``)
    roll is set to 0 and the whole remaining rotation is attributed to yaw. ``R`` is assumed to be a
    rotation; it is not re-orthonormalised.
    """
    m = _as_matrices(R, "R", 3)
    cos_pitch = np.hypot(m[..., 0, 0], m[..., 1, 0])
    # atan2 with the hypot keeps pitch accurate near +-pi/2, unlike arcsin(-R20).
    pitch = np.arctan2(-m[..., 2, 0], cos_pitch)
    locked = cos_pitch < _GIMBAL_EPS
    roll = np.where(locked, 0.0, np.arctan2(m[..., 2, 1], m[..., 2, 2]))
    # With roll = 0 and cos(pitch) = 0, R01 = -sin(yaw) and R11 = cos(yaw) for both signs of pitch.
    yaw = np.where(locked, np.arctan2(-m[..., 0, 1], m[..., 1, 1]), np.arctan2(m[..., 1, 0], m[..., 0, 0]))
    return np.stack([roll, pitch, yaw], axis=-1).astype(np.float64, copy=False)


def pose_to_matrix(xyz: npt.ArrayLike, rpy: npt.ArrayLike) -> FloatArray:
    """Translation ``(..., 3)`` [m] and roll/pitch/yaw ``(..., 3)`` [rad] -> transforms ``(..., 4, 4)``.

    The leading dimensions of ``xyz`` and ``rpy`` broadcast against each other.
    """
    t = _as_vectors(xyz, "xyz")
    rot = rpy_to_matrix(rpy)
    try:
        batch = np.broadcast_shapes(t.shape[:-1], rot.shape[:-2])
    except ValueError as exc:
        raise ValueError(
            f"xyz and rpy batch shapes must broadcast; got xyz {t.shape} and rpy {rot.shape[:-1]}"
        ) from exc
    out = np.zeros((*batch, 4, 4), dtype=np.float64)
    out[..., :3, :3] = rot
    out[..., :3, 3] = t
    out[..., 3, 3] = 1.0
    return out


def matrix_to_pose(T: npt.ArrayLike) -> tuple[FloatArray, FloatArray]:
    """Transforms ``(..., 4, 4)`` -> ``(xyz (..., 3), rpy (..., 3))``, inverse of :func:`pose_to_matrix`."""
    m = _as_matrices(T, "T", 4)
    return m[..., :3, 3].copy(), matrix_to_rpy(m[..., :3, :3])


def invert_transform(T: npt.ArrayLike) -> FloatArray:
    """Inverse of rigid transforms ``(..., 4, 4)``: ``T_b_a`` from ``T_a_b``.

    Uses ``[R^T, -R^T t]`` rather than ``np.linalg.inv``: it is exact for rigid motions, cheaper, and
    keeps the bottom row exactly ``[0, 0, 0, 1]``. The input is assumed rigid (see
    :func:`is_rigid_transform`).
    """
    m = _as_matrices(T, "T", 4)
    rot_t = np.swapaxes(m[..., :3, :3], -1, -2)
    out = np.zeros_like(m)
    out[..., :3, :3] = rot_t
    out[..., :3, 3] = -(rot_t @ m[..., :3, 3, None])[..., 0]
    out[..., 3, 3] = 1.0
    return out


def transform_points(T: npt.ArrayLike, points: npt.ArrayLike) -> FloatArray:
    """Apply transforms ``T`` ``(4, 4)`` or ``(..., 4, 4)`` to ``points`` ``(..., 3)``.

    Batch dimensions of ``T`` (everything before the last two axes) and of ``points`` (everything
    before the last axis) broadcast with numpy rules, so a single ``(4, 4)`` applies to a ``(N, 3)``
    cloud, ``(B, 4, 4)`` with ``(B, 3)`` applies pairwise, and ``(B, 1, 4, 4)`` with ``(N, 3)`` gives
    ``(B, N, 3)``. Returns the transformed points with the broadcast batch shape plus ``(3,)``.
    """
    m = _as_matrices(T, "T", 4)
    p = _as_vectors(points, "points")
    try:
        np.broadcast_shapes(m.shape[:-2], p.shape[:-1])
    except ValueError as exc:
        raise ValueError(
            f"T batch shape {m.shape[:-2]} and points batch shape {p.shape[:-1]} must broadcast "
            f"(T has shape (..., 4, 4), points (..., 3))"
        ) from exc
    return (m[..., :3, :3] @ p[..., None])[..., 0] + m[..., :3, 3]


def is_rigid_transform(T: npt.ArrayLike, atol: float = 1e-6) -> bool:
    """True if every transform in ``T`` ``(..., 4, 4)`` is a proper rigid motion within ``atol``.

    Checks ``R^T R = I``, ``det R = +1`` (no reflections) and a bottom row of ``[0, 0, 0, 1]``. A
    transform containing NaN/inf is not rigid, so this returns False instead of raising; a wrong
    shape is a programming error and raises ``ValueError``.
    """
    if not (np.isfinite(atol) and atol >= 0):
        raise ValueError(f"atol must be a finite non-negative number; got {atol!r}")
    m = np.asarray(T, dtype=np.float64)
    if m.ndim < 2 or m.shape[-2:] != (4, 4):
        raise ValueError(f"T must have shape (..., 4, 4); got shape {m.shape}")
    if not np.all(np.isfinite(m)):
        return False
    rot = m[..., :3, :3]
    eye = np.eye(3)
    orthonormal = np.allclose(np.swapaxes(rot, -1, -2) @ rot, eye, rtol=0.0, atol=atol)
    proper = np.allclose(np.linalg.det(rot), 1.0, rtol=0.0, atol=atol)
    bottom = np.allclose(m[..., 3, :], [0.0, 0.0, 0.0, 1.0], rtol=0.0, atol=atol)
    return bool(orthonormal and proper and bottom)
