"""The small value types of a simulated task: an object's pose, a seeded layout, a placement verdict,
and the point sampler the layouts use."""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray


@dataclass(frozen=True)
class ObjectPose:
    """Where an object is: body origin position (rig frame, metres) and orientation (w, x, y, z)."""

    xyz: tuple[float, float, float]
    quat: tuple[float, float, float, float] = (1.0, 0.0, 0.0, 0.0)

    @staticmethod
    def yawed(x: float, y: float, z: float, yaw: float) -> ObjectPose:
        return ObjectPose((x, y, z), (math.cos(yaw / 2), 0.0, 0.0, math.sin(yaw / 2)))

    @property
    def position(self) -> NDArray[np.float64]:
        return np.array(self.xyz, dtype=np.float64)

    def tilt(self) -> float:
        """Angle between the object's z axis and the vertical [rad]."""
        _, x, y, _ = self.quat
        zz = 1.0 - 2.0 * (x * x + y * y)  # R[2, 2]
        return math.acos(max(-1.0, min(1.0, zz)))


@dataclass(frozen=True)
class Layout:
    """A seeded initial arrangement: object poses and named goal points of the task (rig frame)."""

    seed: int
    poses: Mapping[str, ObjectPose]
    goals: Mapping[str, tuple[float, float, float]]


class LayoutError(RuntimeError):
    """A scatter group that could not be drawn (``group``: its index in the task file's layout)."""

    def __init__(self, group: int, message: str) -> None:
        self.group = group
        super().__init__(message)


@dataclass(frozen=True)
class PlacementCheck:
    """Whether a subtask's object is where it must be, with a human-readable reason."""

    in_place: bool
    reason: str


def sample_positions(
    rng: np.random.Generator,
    n: int,
    *,
    x_range: tuple[float, float],
    y_range: tuple[float, float],
    min_distance: float,
    keep_out: tuple[tuple[float, float, float], ...] = (),
    tries: int = 2000,
) -> list[tuple[float, float]]:
    """``n`` points in a rectangle, pairwise ≥ ``min_distance`` apart and outside (x, y, radius) discs."""
    points: list[tuple[float, float]] = []
    for _ in range(tries):
        x, y = float(rng.uniform(*x_range)), float(rng.uniform(*y_range))
        if any(math.hypot(x - px, y - py) < min_distance for px, py in points):
            continue
        if any(math.hypot(x - kx, y - ky) < r for kx, ky, r in keep_out):
            continue
        points.append((x, y))
        if len(points) == n:
            return points
    raise RuntimeError(f"could not place {n} objects {min_distance} m apart in x {x_range}, y {y_range}")
