"""Cartesian motion for the scripted policies: TCP waypoints → a chunk of absolute joint commands.

A waypoint is a TCP position, a yaw about the vertical (the tool always points straight down) and a
grip value. Segments are eased in and out (smoothstep) at a bounded Cartesian speed, and every step is
solved with the closed-form UR IK nearest to the previous step's joints, so the chunk is continuous
and stays on one IK branch.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from pilworld.geometry import invert_transform
from pilworld.kinematics.dual_arm import ArmMount
from pilworld.kinematics.ik import ik_nearest

YAW_RATE = 3.0  # rad/s, peak tool yaw rate (a UR wrist turns at up to π rad/s)
GRIP_RATE = 1.8  # normalised opening per second: a bit below the simulated gripper's 2/s


@dataclass(frozen=True)
class Waypoint:
    """A TCP target in the rig frame: position [m], yaw [rad], grip (0 closed … 1 open), dwell steps."""

    xyz: tuple[float, float, float]
    yaw: float
    grip: float
    speed: float = 0.35  # m/s on the way to this waypoint
    dwell: int = 0  # control steps to hold here afterwards (e.g. while the fingers close)


def tool_down(xyz: NDArray[np.float64] | tuple[float, float, float], yaw: float) -> NDArray[np.float64]:
    """The rig-frame TCP pose with the tool z pointing down and the closing (tool y) axis at ``yaw`` − 90°."""
    c, s = math.cos(yaw), math.sin(yaw)
    T = np.eye(4)
    T[:3, 0] = (c, s, 0.0)
    T[:3, 1] = (s, -c, 0.0)
    T[:3, 2] = (0.0, 0.0, -1.0)
    T[:3, 3] = xyz
    return T


def tcp_yaw(T_rig_tcp: NDArray[np.float64]) -> float:
    """Yaw of the tool x axis projected on the table (the inverse of :func:`tool_down`'s yaw)."""
    return math.atan2(T_rig_tcp[1, 0], T_rig_tcp[0, 0])


def nearest_equivalent_yaw(yaw: float, reference: float, period: float = math.pi) -> float:
    """``yaw + k·period`` closest to ``reference`` (a parallel gripper is symmetric under a half turn)."""
    return yaw + period * round((reference - yaw) / period)


def _smoothstep(t: NDArray[np.float64]) -> NDArray[np.float64]:
    return t * t * (3.0 - 2.0 * t)


class ArmPlanner:
    """Plans one arm's joint trajectory through TCP waypoints (rig frame) at the control rate."""

    def __init__(self, mount: ArmMount, control_rate_hz: float, lower: NDArray[np.float64], upper: NDArray[np.float64]):
        self.mount = mount
        self.dt = 1.0 / control_rate_hz
        self.lower = lower
        self.upper = upper
        self._T_base_rig = invert_transform(mount.T_rig_base)

    def tcp(self, q: NDArray[np.floating]) -> NDArray[np.float64]:
        return self.mount.tcp_pose(np.asarray(q, dtype=np.float64))

    def solve(self, T_rig_tcp: NDArray[np.float64], seed: NDArray[np.float64]) -> NDArray[np.float64] | None:
        q = ik_nearest(
            self._T_base_rig @ T_rig_tcp, self.mount.dh, seed, self.mount.T_flange_tcp, self.lower, self.upper
        )
        return None if q is None else np.asarray(q, dtype=np.float64)

    def plan(
        self, q0: NDArray[np.floating], grip0: float, waypoints: list[Waypoint], steps: int
    ) -> NDArray[np.float64]:
        """``(steps, 7)`` joint+grip commands from ``q0`` through ``waypoints``, padded with the last one.

        A waypoint the IK cannot reach ends the plan there (the arm holds its last reachable pose), so
        a bad target degrades to standing still rather than a jump.
        """
        q = np.asarray(q0, dtype=np.float64).copy()
        T = self.tcp(q)
        pos, yaw, grip = T[:3, 3].copy(), tcp_yaw(T), float(grip0)
        out: list[NDArray[np.float64]] = []
        for wp in waypoints:
            target = np.asarray(wp.xyz, dtype=np.float64)
            wyaw = nearest_equivalent_yaw(wp.yaw, yaw, 2 * math.pi)
            dist = float(np.linalg.norm(target - pos))
            # Eased segments average 2/3 of their peak speed; the grip moves no faster than the gripper.
            n = max(
                1,
                math.ceil(max(dist / (wp.speed * self.dt), abs(wyaw - yaw) / (YAW_RATE * self.dt)) * 1.5),
                math.ceil(abs(wp.grip - grip) / (GRIP_RATE * self.dt)),
            )
            s = _smoothstep(np.arange(1, n + 1) / n)
            reached = True
            for si in s:
                p = pos + si * (target - pos)
                y = yaw + si * (wyaw - yaw)
                g = grip + si * (wp.grip - grip)
                qn = self.solve(tool_down(p, y), q)
                if qn is None:
                    reached = False
                    break
                q = qn
                out.append(np.append(q, g))
                if len(out) >= steps:
                    return np.stack(out)
            if not reached:
                break
            pos, yaw, grip = target, wyaw, wp.grip
            out.extend([np.append(q, grip)] * wp.dwell)
            if len(out) >= steps:
                return np.stack(out[:steps])
        last = out[-1] if out else np.append(q, grip)
        out.extend([last] * (steps - len(out)))
        return np.stack(out)

    def joint_path(
        self, q0: NDArray[np.floating], grip0: float, q1: NDArray[np.floating], grip1: float, steps: int
    ) -> NDArray[np.float64]:
        """A joint-space move to ``q1`` at ≤ 1 rad/s per joint, padded to ``steps`` rows."""
        a, b = np.asarray(q0, dtype=np.float64), np.asarray(q1, dtype=np.float64)
        n = max(1, math.ceil(float(np.max(np.abs(b - a))) / (1.0 * self.dt) * 1.5))
        s = _smoothstep(np.arange(1, n + 1) / n)[:, None]
        path = np.hstack([a + s * (b - a), grip0 + s * (grip1 - grip0)])
        if len(path) >= steps:
            return path[:steps]
        return np.vstack([path, np.repeat(path[-1:], steps - len(path), axis=0)])
