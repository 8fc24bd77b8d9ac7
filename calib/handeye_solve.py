"""One closed-form hand-eye solver for either camera mount: AX = XB (Park-Martin) or AX = ZB (Shah).

:func:`solve_hand_eye` takes the mount (:class:`calib.handeye_mount.CameraMount`), FK ``G_i`` and PnP
``C_i = T_cam_board[i]``, refuses degenerate motion (:func:`calib.handeye.check_hand_eye_motion`) and solves
for the camera transform ``X`` and the board pose ``Y``. What differs between the mounts is only how the
equations are built from the poses (see docs/calibration.md, "3. Hand-eye"):

* **eye-to-hand** (``X = T_cam_base``, ``Y = T_gripper_board``). AX = XB: for pose pairs ``(i, j)``,
  ``A = C_j C_i⁻¹`` and ``B = G_j G_i⁻¹``; ``Y`` is averaged from ``G_i⁻¹ X⁻¹ C_i`` afterwards.
  AX = ZB: ``C_i · Y⁻¹ = X · G_i`` gives ``(Y⁻¹, X)`` at once.
* **eye-in-hand** (``X = T_tcp_cam``, ``Y = T_base_board``). AX = XB: ``A = G_i⁻¹ G_j`` (the TCP's motion in
  its own frame) and ``B = C_i C_j⁻¹`` (the camera's motion); ``Y`` is averaged from ``G_i X C_i``.
  AX = ZB: ``G_i · X = Y · C_i⁻¹`` gives ``(X, Y)`` at once.

:func:`solve_eye_to_hand` and :func:`solve_eye_in_hand` are the same solver with the mount filled in; their
results name the transforms (``T_cam_base`` … ``T_tcp_cam`` …). Never returns a silent identity.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Final

import numpy as np
import numpy.typing as npt

from calib.handeye import METHODS, Method, MotionReport, check_hand_eye_motion, pose_pairs, solve_ax_xb, solve_ax_zb
from calib.handeye_mount import CameraMount, TransformName
from calib.rotations import as_transforms, nearest_rotation, pose_difference, rigid
from pilworld.geometry import invert_transform

__all__ = [
    "EyeInHandResult",
    "HandEyeResult",
    "HandEyeSolution",
    "average_pose",
    "solve_eye_in_hand",
    "solve_eye_to_hand",
    "solve_hand_eye",
]

FloatArray = npt.NDArray[np.float64]
Poses = Sequence[npt.ArrayLike] | npt.ArrayLike


@dataclass(frozen=True, eq=False)
class HandEyeSolution:
    """A closed-form solution of either mount and how well it explains the input poses."""

    X: FloatArray  #: the camera transform the mount solves for (:attr:`CameraMount.solved`)
    Y: FloatArray  #: the board pose, in the frame the mount puts it in (:attr:`CameraMount.board_pose`)
    method: str
    motion: MotionReport
    #: per pose: (translation error in metres, rotation error in degrees) of the predicted ``T_cam_board[i]``
    #: against the measured one
    pose_residuals: tuple[tuple[float, float], ...]

    @property
    def residual_rms_m(self) -> float:
        return math.sqrt(float(np.mean([t**2 for t, _ in self.pose_residuals])))

    @property
    def residual_rms_deg(self) -> float:
        return math.sqrt(float(np.mean([r**2 for _, r in self.pose_residuals])))


class HandEyeResult(HandEyeSolution):
    """An eye-to-hand solution: a fixed camera and a board in the gripper."""

    T_cam_base = TransformName("X", "Maps base-frame points into the camera frame.")
    T_gripper_board = TransformName("Y", "Maps board-frame points into the gripper frame.")


class EyeInHandResult(HandEyeSolution):
    """An eye-in-hand solution: a camera on the arm and a board fixed in the world."""

    T_tcp_cam = TransformName("X", "Camera-frame points → TCP frame (the wrist mount).")
    T_base_board = TransformName("Y", "Board-frame points → base frame (where the board lies).")

    @property
    def T_cam_tcp(self) -> FloatArray:  # noqa: N802 - the transform's name
        return invert_transform(self.X)


def average_pose(poses: FloatArray) -> FloatArray:
    """The chordal mean of ``(N, 4, 4)`` poses: the nearest rotation to the summed rotations, the mean translation."""
    return rigid(nearest_rotation(poses[:, :3, :3].sum(axis=0)), poses[:, :3, 3].mean(axis=0))


def _eye_to_hand(G: FloatArray, C: FloatArray, method: Method) -> tuple[FloatArray, FloatArray]:
    if method == "park":
        pairs = pose_pairs(G.shape[0])
        A = [C[j] @ invert_transform(C[i]) for i, j in pairs]
        B = [G[j] @ invert_transform(G[i]) for i, j in pairs]
        X = solve_ax_xb(A, B)
        Y = average_pose(np.asarray([invert_transform(g) @ invert_transform(X) @ c for g, c in zip(G, C, strict=True)]))
        return X, Y
    Y_inv, X = solve_ax_zb(C, G)
    return X, invert_transform(Y_inv)


def _eye_in_hand(G: FloatArray, C: FloatArray, method: Method) -> tuple[FloatArray, FloatArray]:
    if method == "park":
        pairs = pose_pairs(G.shape[0])
        A = [invert_transform(G[i]) @ G[j] for i, j in pairs]
        B = [C[i] @ invert_transform(C[j]) for i, j in pairs]
        X = solve_ax_xb(A, B)
        return X, average_pose(np.asarray([g @ X @ c for g, c in zip(G, C, strict=True)]))
    return solve_ax_zb(G, invert_transform(C))


def _predicted_cam_board(mount: CameraMount, X: FloatArray, Y: FloatArray, G: FloatArray) -> list[FloatArray]:
    """``T_cam_board[i]`` as the solution predicts it (the model of :mod:`calib.handeye_mount`)."""
    if mount is CameraMount.EYE_TO_HAND:
        return [X @ g @ Y for g in G]
    X_inv = invert_transform(X)
    return [X_inv @ invert_transform(g) @ Y for g in G]


_CLOSED_FORMS: Final[dict[CameraMount, Callable[[FloatArray, FloatArray, Method], tuple[FloatArray, FloatArray]]]] = {
    CameraMount.EYE_TO_HAND: _eye_to_hand,
    CameraMount.EYE_IN_HAND: _eye_in_hand,
}
_RESULTS: Final[dict[CameraMount, type[HandEyeSolution]]] = {
    CameraMount.EYE_TO_HAND: HandEyeResult,
    CameraMount.EYE_IN_HAND: EyeInHandResult,
}


def solve_hand_eye(
    mount: CameraMount,
    T_base_gripper: Poses,
    T_cam_board: Poses,
    method: Method = "shah",
    min_rotation_span_deg: float = 5.0,
    min_axis_spread: float = 0.1,
) -> HandEyeSolution:
    """Closed-form camera transform ``X`` and board pose ``Y`` of ``mount`` (see the module docstring).

    Raises :class:`calib.handeye.DegenerateMotionError` for degenerate motion (for a wrist camera naming the
    motion to add) and ``ValueError`` for mismatched or non-rigid inputs.
    """
    G = as_transforms(T_base_gripper, mount.fk)
    C = as_transforms(T_cam_board, "T_cam_board")
    if G.shape[0] != C.shape[0]:
        raise ValueError(f"{mount.fk} and T_cam_board must pair up one to one, got {G.shape[0]} and {C.shape[0]} poses")
    if method not in METHODS:
        raise ValueError(f"method: expected one of {', '.join(METHODS)}, got {method!r}")
    motion = check_hand_eye_motion(mount, G, min_rotation_span_deg, min_axis_spread)
    X, Y = _CLOSED_FORMS[mount](G, C, method)
    residuals = tuple(pose_difference(p, c) for p, c in zip(_predicted_cam_board(mount, X, Y, G), C, strict=True))
    return _RESULTS[mount](X=X, Y=Y, method=method, motion=motion, pose_residuals=residuals)


def solve_eye_to_hand(
    T_base_gripper: Poses,
    T_cam_board: Poses,
    method: Method = "shah",
    min_rotation_span_deg: float = 5.0,
    min_axis_spread: float = 0.1,
) -> HandEyeResult:
    """:func:`solve_hand_eye` for a fixed camera and a board in the gripper: ``T_cam_base``, ``T_gripper_board``."""
    mount = CameraMount.EYE_TO_HAND
    result = solve_hand_eye(mount, T_base_gripper, T_cam_board, method, min_rotation_span_deg, min_axis_spread)
    assert isinstance(result, HandEyeResult)  # the mount's result class (_RESULTS)
    return result


def solve_eye_in_hand(
    T_base_tcp: Poses,
    T_cam_board: Poses,
    method: Method = "shah",
    min_rotation_span_deg: float = 5.0,
    min_axis_spread: float = 0.1,
) -> EyeInHandResult:
    """:func:`solve_hand_eye` for a camera on the arm and a fixed board: ``T_tcp_cam``, ``T_base_board``."""
    mount = CameraMount.EYE_IN_HAND
    result = solve_hand_eye(mount, T_base_tcp, T_cam_board, method, min_rotation_span_deg, min_axis_spread)
    assert isinstance(result, EyeInHandResult)  # the mount's result class (_RESULTS)
    return result
