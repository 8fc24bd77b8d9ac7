"""A conservative capsule model of a UR arm with its gripper, to keep planned board views unoccluded.

The pose planner has no renderer (it must work for a real rig too), so it tests geometry: every
line of sight from the camera centre to a board point must clear every capsule of both arms by a
margin, and the board plate must not pass through the holding arm's links. The capsules enclose the
simulated rig's visuals (link capsules, joint housings, coupling, palm and open fingers, see
``simrig.scene``) and are generous enough for a real UR5e with a parallel gripper.
"""

from __future__ import annotations

from typing import Final

import numpy as np
import numpy.typing as npt

from pilworld.kinematics.dual_arm import ArmMount
from pilworld.kinematics.fk import fk_frames

__all__ = ["ArmCapsules", "arm_capsules", "segment_distances"]

FloatArray = npt.NDArray[np.float64]

LINK_RADIUS: Final = 0.065  # m, around the DH offsets between joint origins (the arm's links)
HOUSING_RADIUS: Final = 0.06  # m, joint housings along each joint axis
HOUSING_HALF_LENGTH: Final = 0.07  # m
GRIPPER_RADIUS: Final = 0.065  # m, coupling, palm and open fingers around the tool axis, flange to TCP


class ArmCapsules:
    """Capsules ``(start, end, radius)`` in the rig frame; ``gripper`` marks the flange→TCP capsule."""

    def __init__(self, start: FloatArray, end: FloatArray, radius: FloatArray, gripper: npt.NDArray[np.bool_]) -> None:
        self.start, self.end, self.radius, self.gripper = start, end, radius, gripper

    def __add__(self, other: ArmCapsules) -> ArmCapsules:
        return ArmCapsules(
            np.concatenate([self.start, other.start]),
            np.concatenate([self.end, other.end]),
            np.concatenate([self.radius, other.radius]),
            np.concatenate([self.gripper, other.gripper]),
        )

    def links(self) -> ArmCapsules:
        """The capsules without the gripper's."""
        keep = ~self.gripper
        return ArmCapsules(self.start[keep], self.end[keep], self.radius[keep], self.gripper[keep])


def arm_capsules(mount: ArmMount, q: npt.ArrayLike) -> ArmCapsules:
    """The capsules of one arm at joint angles ``q`` ``(6,)`` (rig frame)."""
    frames = mount.T_rig_base @ fk_frames(np.asarray(q, dtype=np.float64), mount.dh)  # (7, 4, 4), flange last
    origins, axes = frames[:, :3, 3], frames[:, :3, 2]
    tcp = (frames[6] @ mount.T_flange_tcp)[:3, 3]
    starts = [origins[:6], origins[:6] - HOUSING_HALF_LENGTH * axes[:6], origins[6:7]]
    ends = [origins[1:7], origins[:6] + HOUSING_HALF_LENGTH * axes[:6], tcp[None]]
    radii = [np.full(6, LINK_RADIUS), np.full(6, HOUSING_RADIUS), np.array([GRIPPER_RADIUS])]
    gripper = np.zeros(13, dtype=bool)
    gripper[-1] = True
    return ArmCapsules(np.concatenate(starts), np.concatenate(ends), np.concatenate(radii), gripper)


def segment_distances(p0: FloatArray, p1: FloatArray, q0: FloatArray, q1: FloatArray) -> FloatArray:
    """Closest distances between segments ``p0→p1`` ``(M, 3)`` and ``q0→q1`` ``(N, 3)``, as ``(M, N)``.

    The standard clamped closest-point computation (e.g. Ericson, *Real-Time Collision Detection*, §5.1.9),
    vectorised; degenerate (zero-length) segments are handled as points.
    """
    d1 = (p1 - p0)[:, None, :]
    d2 = (q1 - q0)[None, :, :]
    r = p0[:, None, :] - q0[None, :, :]
    a = np.sum(d1 * d1, axis=-1)
    e = np.sum(d2 * d2, axis=-1)
    f = np.sum(d2 * r, axis=-1)
    c = np.sum(d1 * r, axis=-1)
    b = np.sum(d1 * d2, axis=-1)
    eps = 1e-15
    denom = a * e - b * b
    s = np.where(denom > eps, np.clip((b * f - c * e) / np.maximum(denom, eps), 0.0, 1.0), 0.0)
    t = (b * s + f) / np.maximum(e, eps)
    # t outside [0, 1]: clamp it and recompute s for the clamped t.
    t_lo, t_hi = t < 0.0, t > 1.0
    s = np.where(t_lo, np.clip(-c / np.maximum(a, eps), 0.0, 1.0), s)
    s = np.where(t_hi, np.clip((b - c) / np.maximum(a, eps), 0.0, 1.0), s)
    t = np.clip(t, 0.0, 1.0)
    # Point cases: a first segment of zero length (s = 0), a second one (t = 0), or both.
    p_point, q_point = a <= eps, e <= eps
    s = np.where(q_point, np.clip(-c / np.maximum(a, eps), 0.0, 1.0), s)
    t = np.where(q_point, 0.0, t)
    t = np.where(p_point, np.clip(f / np.maximum(e, eps), 0.0, 1.0), t)
    s = np.where(p_point, 0.0, s)
    t = np.where(p_point & q_point, 0.0, t)
    diff = (p0[:, None, :] + s[..., None] * d1) - (q0[None, :, :] + t[..., None] * d2)
    out: FloatArray = np.linalg.norm(diff, axis=-1)
    return out
