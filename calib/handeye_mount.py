"""Where the camera is mounted: the one parameter that separates the two hand-eye problems.

For each pose ``i``, ``G_i`` (4x4) is forward kinematics (gripper or TCP frame → base or rig frame) and
``C_i = T_cam_board[i]`` (board frame → camera frame, from ``solvePnP``). Two constants are unknown:

* :attr:`CameraMount.EYE_TO_HAND`: the camera is fixed in the world (the head camera) and the board rides
  on the gripper: ``C_i = X · G_i · Y`` with ``X = T_cam_base`` (base → camera: what is solved) and
  ``Y = T_gripper_board`` (the board lies in the gripper frame).
* :attr:`CameraMount.EYE_IN_HAND`: the camera rides on the gripper (a wrist camera) and the board is fixed
  in the world: ``G_i · X · C_i = Y`` with ``X = T_tcp_cam`` (camera → TCP: the wrist mount) and
  ``Y = T_base_board`` (the board lies in the base frame).

Rewritten, eye-in-hand is eye-to-hand with ``X := X⁻¹``, ``G_i := G_i⁻¹`` (:meth:`CameraMount.fixed_camera`):
``C_i = X⁻¹ · G_i⁻¹ · Y``. So the pixel model, its refinement and OpenCV's cross-check are written once for
the fixed camera (:mod:`calib.handeye_refine`) and serve both mounts; only the closed forms and the advice
on degenerate motion differ (:mod:`calib.handeye_solve`, :mod:`calib.handeye`). See docs/calibration.md,
"3. Hand-eye" and "Wrist cameras (eye-in-hand)".
"""

from __future__ import annotations

from enum import Enum
from operator import attrgetter
from typing import overload

import numpy as np
import numpy.typing as npt

from pilworld.geometry import invert_transform

__all__ = ["CameraMount", "TransformName"]

FloatArray = npt.NDArray[np.float64]


class CameraMount(Enum):
    """Where the camera is: fixed in the world (eye-to-hand) or on the gripper (eye-in-hand)."""

    EYE_TO_HAND = "eye_to_hand"
    EYE_IN_HAND = "eye_in_hand"

    @property
    def solved(self) -> str:
        """The name of the camera transform ``X`` that is solved."""
        return "T_cam_base" if self is CameraMount.EYE_TO_HAND else "T_tcp_cam"

    @property
    def board_pose(self) -> str:
        """The name of the board pose ``Y``: in the gripper frame (eye-to-hand) or the base frame (eye-in-hand)."""
        return "T_gripper_board" if self is CameraMount.EYE_TO_HAND else "T_base_board"

    @property
    def fk(self) -> str:
        """The name the solvers give the forward kinematics ``G_i`` in their messages."""
        return "T_base_gripper" if self is CameraMount.EYE_TO_HAND else "T_base_tcp"

    def fixed_camera(self, T: FloatArray) -> FloatArray:
        """``X`` or FK ``G_i`` (``(4, 4)`` or ``(N, 4, 4)``) as the equivalent fixed camera's ``T_cam_base`` or FK.

        Identity for eye-to-hand, inversion for eye-in-hand: the map is its own inverse, so it also takes the
        fixed camera's ``T_cam_base`` back to this mount's ``X``.
        """
        return T if self is CameraMount.EYE_TO_HAND else invert_transform(T)


class TransformName:
    """A read-only attribute naming one of a result's transforms as its mount does (``T_cam_base`` for ``X`` …).

    The solvers of both mounts share one code path on ``X`` and ``Y``; the result classes give them the names a
    user of that mount reads. ``path`` is the attribute (dotted: ``"refined.X"``) it reads.
    """

    def __init__(self, path: str, doc: str) -> None:
        self._get = attrgetter(path)
        self.__doc__ = doc

    @overload
    def __get__(self, obj: None, owner: type) -> TransformName: ...
    @overload
    def __get__(self, obj: object, owner: type | None = None) -> FloatArray: ...
    def __get__(self, obj: object, owner: type | None = None) -> TransformName | FloatArray:
        if obj is None:
            return self
        value: FloatArray = self._get(obj)
        return value
