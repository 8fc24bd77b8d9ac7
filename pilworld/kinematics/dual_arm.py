"""Dual-arm kinematics: gripper points in the rig frame from a 14-d joint vector.

The rig frame is the common frame of a dual-arm set-up (for the simulated rig: origin on the table
surface, x forward, y left, z up). Each arm contributes ``T_rig_base`` (where its base sits) and
``T_flange_tcp`` (its gripper's tool centre point, between the fingertips); the control video and the
calibration check both go through :meth:`DualArmKinematics.gripper_points`.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from pilworld.geometry import as_finite_array, is_rigid_transform
from pilworld.kinematics.fk import fk
from pilworld.kinematics.ur_dh import DHParams
from pilworld.types import LEFT_ARM, LEFT_GRIP, RIGHT_ARM, RIGHT_GRIP, STATE_DIM


@dataclass(frozen=True, eq=False)
class ArmMount:
    """One arm of the rig: its DH model, its base pose in the rig frame and its flange→TCP offset."""

    dh: DHParams
    T_rig_base: NDArray[np.float64]  # (4, 4): base-frame points → rig frame
    T_flange_tcp: NDArray[np.float64]  # (4, 4): TCP-frame points → flange frame

    def __post_init__(self) -> None:
        for name in ("T_rig_base", "T_flange_tcp"):
            T = np.asarray(getattr(self, name), dtype=np.float64)
            if T.shape != (4, 4) or not is_rigid_transform(T):
                raise ValueError(f"{name}: expected a rigid 4x4 transform, got {T!r}")
            T = T.copy()
            T.flags.writeable = False
            object.__setattr__(self, name, T)

    def tcp_pose(self, q: NDArray[np.floating]) -> NDArray[np.float64]:
        """(..., 6) joint angles → (..., 4, 4) TCP pose in the rig frame."""
        return self.T_rig_base @ fk(q, self.dh, self.T_flange_tcp)


@dataclass(frozen=True, eq=False)
class DualArmKinematics:
    """Left and right arm mounts; maps 14-d ``[L j1..j6, L grip, R j1..j6, R grip]`` vectors to TCPs."""

    left: ArmMount
    right: ArmMount

    def _check(self, q14: NDArray[np.floating]) -> NDArray[np.float64]:
        return as_finite_array(q14, "q14", (STATE_DIM,))

    def tcp_poses(self, q14: NDArray[np.floating]) -> NDArray[np.float64]:
        """(..., 14) → (..., 2, 4, 4) left and right TCP poses in the rig frame."""
        q = self._check(q14)
        return np.stack([self.left.tcp_pose(q[..., LEFT_ARM]), self.right.tcp_pose(q[..., RIGHT_ARM])], axis=-3)

    def gripper_points(self, q14: NDArray[np.floating]) -> NDArray[np.float64]:
        """(..., 14) → (..., 2, 3) left and right TCP positions in the rig frame (metres)."""
        return self.tcp_poses(q14)[..., :3, 3]

    @staticmethod
    def gripper_openings(q14: NDArray[np.floating]) -> NDArray[np.float64]:
        """(..., 14) → (..., 2) left and right grip values, 0 = closed … 1 = open (not clipped)."""
        q = np.asarray(q14, dtype=np.float64)
        return np.stack([q[..., LEFT_GRIP], q[..., RIGHT_GRIP]], axis=-1)
