"""Hand-eye building blocks: the motion check of either mount and the closed forms AX = XB and AX = ZB.

Inputs, for each pose ``i`` (N >= 3): ``G_i`` (4x4) forward kinematics (gripper-frame points → base frame,
OpenCV's "gripper2base"; "gripper" is whatever frame FK ends in, flange or TCP; for a dual-arm rig pass
rig-frame poses to get rig-frame results) and ``C_i = T_cam_board[i]`` (board-frame points → camera frame,
``solvePnP``'s rvec/tvec, OpenCV's "target2cam"). How the two unknown constants enter depends on where the
camera is (:class:`calib.handeye_mount.CameraMount`); :func:`calib.handeye_solve.solve_hand_eye` is the one
entry that builds the equations below for either mount.

* **AX = XB** (:func:`solve_ax_xb`, Park & Martin 1994): for relative motions ``A_k``, ``B_k``. The rotation
  vectors obey ``α = R_X β``; ``R_X`` is the least-squares rotation (Kabsch/SVD form of Park-Martin's
  ``(MᵀM)^(-1/2) Mᵀ``), then ``(R_A - I) t_X = R_X t_B - t_A`` is solved by linear least squares.
* **AX = ZB** (:func:`solve_ax_zb`, Shah 2013): for absolute poses. The rotations satisfy the linear system
  ``(I ⊗ R_A) vec(R_X) = (R_Bᵀ ⊗ I) vec(R_Z)``, whose null vector (SVD) gives both rotations up to scale;
  they are rescaled to det 1 and projected onto SO(3); the translations follow from
  ``R_A t_X + t_A = R_Z t_B + t_Z`` by linear least squares.

Before solving, :func:`check_motion` refuses motion that cannot determine the answer, with
:class:`DegenerateMotionError` naming the cause: fewer than 3 poses, a small rotation span (every
method, and OpenCV's TSAI silently returns the identity, see shared/REFERENCES.md) or rotations about a
single axis (the translation along that axis is then unobservable). For a wrist camera,
:func:`check_eye_in_hand_motion` runs the same test on the TCP motion and names the motion to add
(**pure translation**: "add rotations about two different axes"; a single axis: "add rotations about a
second axis"). Closed forms minimise algebraic errors; :mod:`calib.handeye_refine` then minimises the
pixel reprojection error.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Final, Literal

import numpy as np
import numpy.typing as npt

from calib.handeye_mount import CameraMount
from calib.rotations import as_transforms, nearest_rotation, rigid, rotation_angle, rotation_log
from pilworld.geometry import invert_transform

__all__ = [
    "ADD_ROTATIONS",
    "METHODS",
    "DegenerateMotionError",
    "Method",
    "MotionReport",
    "check_eye_in_hand_motion",
    "check_hand_eye_motion",
    "check_motion",
    "pose_pairs",
    "solve_ax_xb",
    "solve_ax_zb",
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


def pose_pairs(n: int) -> list[tuple[int, int]]:
    """Every pair ``(i, j)``, ``i < j``, of ``n`` poses: the relative motions the checks and AX = XB use."""
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
    for i, j in pose_pairs(n):
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


#: Advice appended to every refusal of a wrist camera's motion: what a user moves to fix it.
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
    """:func:`check_motion` on the TCP motion, with messages for a wrist camera.

    The test runs on ``T_base_tcp[i]⁻¹`` so a single rotation axis is reported in the TCP frame, the frame
    the user tilts the camera in. Raises :class:`DegenerateMotionError` whose message starts with the
    cause (``pure translation``, ``too few poses``, ``rotations about a single axis``) and names the motion
    to add.
    """
    G = as_transforms(T_base_tcp, "T_base_tcp")
    n = G.shape[0]
    if n >= 2:
        span = max(math.degrees(rotation_angle(G[j, :3, :3].T @ G[i, :3, :3])) for i, j in pose_pairs(n))
        if span <= min_rotation_span_deg:
            moved = max(float(np.linalg.norm(G[j, :3, 3] - G[i, :3, 3])) for i, j in pose_pairs(n))
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
    for i, j in pose_pairs(G.shape[0]):
        R = G[i, :3, :3].T @ G[j, :3, :3]
        if math.degrees(rotation_angle(R)) >= 1.0:
            w = np.array([R[2, 1] - R[1, 2], R[0, 2] - R[2, 0], R[1, 0] - R[0, 1]])
            axes.append(w / max(float(np.linalg.norm(w)), 1e-300))
    if not axes:
        return np.zeros(3)
    A = np.asarray(axes)
    out: FloatArray = np.linalg.eigh(A.T @ A)[1][:, -1]
    return out * (1.0 if out[np.argmax(np.abs(out))] > 0 else -1.0)


def check_hand_eye_motion(
    mount: CameraMount,
    T_base_gripper: Sequence[npt.ArrayLike] | npt.ArrayLike,
    min_rotation_span_deg: float = 5.0,
    min_axis_spread: float = 0.1,
) -> MotionReport:
    """The motion check of ``mount``: :func:`check_motion` or, for a wrist camera, :func:`check_eye_in_hand_motion`."""
    check = check_motion if mount is CameraMount.EYE_TO_HAND else check_eye_in_hand_motion
    return check(T_base_gripper, min_rotation_span_deg=min_rotation_span_deg, min_axis_spread=min_axis_spread)
