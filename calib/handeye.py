"""Eye-to-hand calibration of a fixed camera with a board held by a gripper: closed-form AX = XB and AX = ZB.

Inputs, for each pose ``i`` (N >= 3):

* ``T_base_gripper[i]`` (4x4): forward kinematics, maps gripper-frame points into the robot base frame
  (OpenCV's "gripper2base"). "Gripper" is whatever frame FK ends in (flange or TCP) -- the board only has
  to be rigidly attached to it. For a dual-arm rig pass rig-frame poses to get the rig-frame camera.
* ``T_cam_board[i]`` (4x4): maps board-frame points into the camera frame (``solvePnP``'s rvec/tvec,
  OpenCV's "target2cam").

Model: ``T_cam_board[i] = T_cam_base · T_base_gripper[i] · T_gripper_board`` with two unknown constants,
``T_cam_base`` (maps base-frame points into the camera frame, as :class:`calib.camera_model.CameraModel`
stores it) and ``T_gripper_board``.

* **AX = XB** (``method="park"``, Park & Martin 1994): for pose pairs ``(i, j)``,
  ``A = T_cam_board[j] T_cam_board[i]⁻¹`` and ``B = T_base_gripper[j] T_base_gripper[i]⁻¹`` satisfy
  ``A X = X B`` with ``X = T_cam_base``. The rotation vectors obey ``α = R_X β``; ``R_X`` is the least-squares
  rotation (Kabsch/SVD form of Park-Martin's ``(MᵀM)^(-1/2) Mᵀ``), then ``(R_A - I) t_X = R_X t_B - t_A``
  is solved by linear least squares. ``T_gripper_board`` is averaged from the poses afterwards.
* **AX = ZB** (``method="shah"``, Shah 2013): ``T_cam_board[i] X = Z T_base_gripper[i]`` with
  ``X = T_gripper_board⁻¹`` and ``Z = T_cam_base``. The rotations satisfy the linear system
  ``(I ⊗ R_A) vec(R_X) = (R_Bᵀ ⊗ I) vec(R_Z)``, whose null vector (SVD) gives both rotations up to scale;
  they are rescaled to det 1 and projected onto SO(3); the translations follow from
  ``R_A t_X + t_A = R_Z t_B + t_Z`` by linear least squares.

Before solving, :func:`check_motion` refuses motion that cannot determine the answer, with
:class:`DegenerateMotionError` naming the cause: fewer than 3 poses, a small rotation span (every
method, and OpenCV's TSAI silently returns the identity, see shared/REFERENCES.md) or rotations about a
single axis (the translation along that axis is then unobservable). Closed forms minimise algebraic
errors; :mod:`calib.handeye_refine` then minimises the pixel reprojection error.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Final, Literal

import numpy as np
import numpy.typing as npt

from calib.rotations import as_transforms, nearest_rotation, pose_difference, rigid, rotation_angle, rotation_log
from pilworld.geometry import invert_transform

__all__ = [
    "DegenerateMotionError",
    "HandEyeResult",
    "MotionReport",
    "check_motion",
    "solve_ax_xb",
    "solve_ax_zb",
    "solve_eye_to_hand",
]

FloatArray = npt.NDArray[np.float64]
Method = Literal["park", "shah"]
METHODS: Final = ("park", "shah")

# Pairs rotating less than this carry no usable axis (their axis is mostly noise).
_MIN_PAIR_ANGLE_DEG: Final = 1.0
# Near 180° the sign of a rotation vector is ambiguous; such pairs are left out of AX = XB's rotation step.
_MAX_PAIR_ANGLE_DEG: Final = 175.0


class DegenerateMotionError(ValueError):
    """The robot motion cannot determine the hand-eye transform; the message names the cause and the fix."""


@dataclass(frozen=True)
class MotionReport:
    """How informative the gripper motion is (computed from ``T_base_gripper``)."""

    n_poses: int
    rotation_span_deg: float  #: largest rotation between any two gripper poses
    #: sqrt of the second eigenvalue of the mean outer product of the pairs' unit rotation axes: 0 if all
    #: rotations share one axis, ~sin(θ/2) for two equally used axes θ apart, up to 1/√2 (two orthogonal axes).
    axis_spread: float


def _pairs(n: int) -> list[tuple[int, int]]:
    return [(i, j) for i in range(n) for j in range(i + 1, n)]


def check_motion(
    T_base_gripper: Sequence[npt.ArrayLike] | npt.ArrayLike,
    min_poses: int = 3,
    min_rotation_span_deg: float = 5.0,
    min_axis_spread: float = 0.1,
) -> MotionReport:
    """Measure the gripper motion and raise :class:`DegenerateMotionError` if it is degenerate.

    Only two distinct rotation axes are needed (AX = XB is solvable from rotations about x and y alone),
    so the test is on the *second* largest spread of the axes, not the smallest.
    """
    G = as_transforms(T_base_gripper, "T_base_gripper")
    n = G.shape[0]
    if n < max(min_poses, 3):
        raise DegenerateMotionError(
            f"too few poses: got {n}, need at least {max(min_poses, 3)} (two relative motions with different "
            "rotation axes); record more poses"
        )
    angles, axes = [], []
    for i, j in _pairs(n):
        R = G[j, :3, :3] @ G[i, :3, :3].T
        theta = rotation_angle(R)
        angles.append(theta)
        if math.degrees(theta) >= _MIN_PAIR_ANGLE_DEG:
            w = rotation_log(R)
            axes.append(w / np.linalg.norm(w))
    span = math.degrees(max(angles))
    if span <= min_rotation_span_deg or not axes:  # no axes: only possible with min_rotation_span_deg < 1°
        raise DegenerateMotionError(
            f"rotation span too small: the gripper orientations differ by at most {span:.2f}° (need more than "
            f"min_rotation_span_deg = {min_rotation_span_deg}° and {_MIN_PAIR_ANGLE_DEG}°); rotate the board by "
            "tens of degrees between poses (small rotations make every method ill-conditioned: errors of centimetres)"
        )
    A = np.asarray(axes)
    eig = np.sort(np.linalg.eigvalsh(A.T @ A / A.shape[0]))[::-1]
    spread = math.sqrt(max(float(eig[1]), 0.0))
    if spread < min_axis_spread:
        main = np.linalg.eigh(A.T @ A)[1][:, -1]
        raise DegenerateMotionError(
            f"rotations about a single axis: the relative rotation axes have spread {spread:.4f} "
            f"(< min_axis_spread = {min_axis_spread}), all close to {np.round(main, 3).tolist()} in the base frame; "
            "the translation along that axis is unobservable. Tilt the board about at least two different axes"
        )
    return MotionReport(n_poses=n, rotation_span_deg=span, axis_spread=spread)


def solve_ax_xb(A: Sequence[npt.ArrayLike] | npt.ArrayLike, B: Sequence[npt.ArrayLike] | npt.ArrayLike) -> FloatArray:
    """``X`` (4x4) with ``A[k] X = X B[k]`` for relative motions ``A[k]``, ``B[k]`` (Park-Martin, least squares).

    Raises ``DegenerateMotionError`` if fewer than two motions rotate usefully (see the module docstring).
    """
    As, Bs = as_transforms(A, "A"), as_transforms(B, "B")
    if As.shape != Bs.shape:
        raise ValueError(f"A and B must have the same number of motions, got {As.shape[0]} and {Bs.shape[0]}")
    alphas, betas = [], []
    for a, b in zip(As, Bs, strict=True):
        theta = math.degrees(rotation_angle(b[:3, :3]))
        if _MIN_PAIR_ANGLE_DEG <= theta <= _MAX_PAIR_ANGLE_DEG:
            alphas.append(rotation_log(a[:3, :3]))
            betas.append(rotation_log(b[:3, :3]))
    if len(alphas) < 2:
        raise DegenerateMotionError(
            f"AX = XB: only {len(alphas)} motion(s) rotate by {_MIN_PAIR_ANGLE_DEG}..{_MAX_PAIR_ANGLE_DEG}°; need two "
            "with different axes"
        )
    M = np.asarray(betas).T @ np.asarray(alphas)  # Σ β αᵀ
    U, _, Vt = np.linalg.svd(M)
    d = float(np.sign(np.linalg.det(Vt.T @ U.T))) or 1.0
    R_X = Vt.T @ np.diag([1.0, 1.0, d]) @ U.T  # argmin Σ |α - R β|²
    C = np.concatenate([a[:3, :3] - np.eye(3) for a in As])
    rhs = np.concatenate([R_X @ b[:3, 3] - a[:3, 3] for a, b in zip(As, Bs, strict=True)])
    t_X = np.linalg.lstsq(C, rhs, rcond=None)[0]
    return rigid(R_X, t_X)


def solve_ax_zb(
    A: Sequence[npt.ArrayLike] | npt.ArrayLike, B: Sequence[npt.ArrayLike] | npt.ArrayLike
) -> tuple[FloatArray, FloatArray]:
    """``(X, Z)`` (4x4 each) with ``A[i] X = Z B[i]`` for absolute poses ``A[i]``, ``B[i]`` (Shah's closed form)."""
    As, Bs = as_transforms(A, "A"), as_transforms(B, "B")
    if As.shape != Bs.shape:
        raise ValueError(f"A and B must have the same number of poses, got {As.shape[0]} and {Bs.shape[0]}")
    eye = np.eye(3)
    # vec() is column-major: vec(P Q R) = (Rᵀ ⊗ P) vec(Q).
    rows = [np.hstack([np.kron(eye, a[:3, :3]), -np.kron(b[:3, :3].T, eye)]) for a, b in zip(As, Bs, strict=True)]
    _, _, Vt = np.linalg.svd(np.vstack(rows))
    v = Vt[-1]
    R_X = v[:9].reshape(3, 3, order="F")
    R_Z = v[9:].reshape(3, 3, order="F")
    scale = np.cbrt(np.linalg.det(R_X))  # the null vector has arbitrary scale and sign
    if not abs(scale) > 1e-12:
        raise DegenerateMotionError("AX = ZB: the rotation system has no well-defined solution (degenerate poses)")
    R_X, R_Z = nearest_rotation(R_X / scale), nearest_rotation(R_Z / scale)
    C = np.vstack([np.hstack([a[:3, :3], -eye]) for a in As])
    rhs = np.concatenate([R_Z @ b[:3, 3] - a[:3, 3] for a, b in zip(As, Bs, strict=True)])
    t = np.linalg.lstsq(C, rhs, rcond=None)[0]
    return rigid(R_X, t[:3]), rigid(R_Z, t[3:])


@dataclass(frozen=True, eq=False)
class HandEyeResult:
    """An eye-to-hand solution and how well it explains the input poses."""

    T_cam_base: FloatArray  #: maps base-frame points into the camera frame
    T_gripper_board: FloatArray  #: maps board-frame points into the gripper frame
    method: str
    motion: MotionReport
    #: per pose: (translation error in metres, rotation error in degrees) of T_cam_base G_i T_gripper_board
    #: against the measured T_cam_board[i]
    pose_residuals: tuple[tuple[float, float], ...]

    @property
    def residual_rms_m(self) -> float:
        return math.sqrt(float(np.mean([t**2 for t, _ in self.pose_residuals])))

    @property
    def residual_rms_deg(self) -> float:
        return math.sqrt(float(np.mean([r**2 for _, r in self.pose_residuals])))


def _average_pose(poses: FloatArray) -> FloatArray:
    return rigid(nearest_rotation(poses[:, :3, :3].sum(axis=0)), poses[:, :3, 3].mean(axis=0))


def solve_eye_to_hand(
    T_base_gripper: Sequence[npt.ArrayLike] | npt.ArrayLike,
    T_cam_board: Sequence[npt.ArrayLike] | npt.ArrayLike,
    method: Method = "shah",
    min_rotation_span_deg: float = 5.0,
    min_axis_spread: float = 0.1,
) -> HandEyeResult:
    """Closed-form ``T_cam_base`` and ``T_gripper_board`` for a fixed camera and a board in the gripper.

    See the module docstring for the conventions. Raises :class:`DegenerateMotionError` for degenerate
    motion and ``ValueError`` for mismatched or non-rigid inputs; never returns a silent identity.
    """
    G = as_transforms(T_base_gripper, "T_base_gripper")
    C = as_transforms(T_cam_board, "T_cam_board")
    if G.shape[0] != C.shape[0]:
        raise ValueError(
            f"T_base_gripper and T_cam_board must pair up one to one, got {G.shape[0]} and {C.shape[0]} poses"
        )
    if method not in METHODS:
        raise ValueError(f"method: expected one of {', '.join(METHODS)}, got {method!r}")
    motion = check_motion(G, min_rotation_span_deg=min_rotation_span_deg, min_axis_spread=min_axis_spread)
    if method == "park":
        pairs = _pairs(G.shape[0])
        A = [C[j] @ invert_transform(C[i]) for i, j in pairs]
        B = [G[j] @ invert_transform(G[i]) for i, j in pairs]
        X = solve_ax_xb(A, B)
        Y = _average_pose(
            np.asarray([invert_transform(g) @ invert_transform(X) @ c for g, c in zip(G, C, strict=True)])
        )
    else:
        X_bg, X = solve_ax_zb(C, G)
        Y = invert_transform(X_bg)
    residuals = tuple(pose_difference(X @ g @ Y, c) for g, c in zip(G, C, strict=True))
    return HandEyeResult(T_cam_base=X, T_gripper_board=Y, method=method, motion=motion, pose_residuals=residuals)
