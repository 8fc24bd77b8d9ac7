"""What a simulated task is: objects and fixtures, a seeded layout, subtask goals and a privileged checker.

Following dm_control, each concern is its own method: the scene content (:meth:`Task.objects`,
:meth:`Task.fixtures`), the initial state (:meth:`Task.layout`), the state after earlier subtasks are
done (:meth:`Task.completed_poses`), and success (:meth:`Task.in_place`). "Released" and "stable for a
while" are checked by the simulator for every task alike (see ``SimRobot.check_subtask``).
"""

from __future__ import annotations

import math
from abc import ABC, abstractmethod
from collections.abc import Mapping
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from hw_drivers.sim.objects import FixtureSpec, ObjectSpec


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


@dataclass(frozen=True)
class PlacementCheck:
    """Whether a subtask's object is where it must be, with a human-readable reason."""

    in_place: bool
    reason: str


class Task(ABC):
    """One simulated task; subclasses are small and registered by name in ``hw_drivers.sim.tasks``."""

    name: str
    instruction: str  # the paper's instruction, verbatim
    num_subtasks: int

    @abstractmethod
    def objects(self) -> tuple[ObjectSpec, ...]:
        """The free objects of the scene (their names are unique within the task)."""

    def fixtures(self) -> tuple[FixtureSpec, ...]:
        """Static decorations (slot outlines, a target mark)."""
        return ()

    @abstractmethod
    def layout(self, seed: int) -> Layout:
        """A random initial arrangement for ``seed`` (deterministic)."""

    @abstractmethod
    def subtask_object(self, index: int) -> str:
        """The object moved in subtask ``index``."""

    @abstractmethod
    def completed_poses(self, layout: Layout, done: int) -> dict[str, ObjectPose]:
        """Object poses once subtasks ``0 … done−1`` have succeeded (others as in ``layout``)."""

    @abstractmethod
    def in_place(self, layout: Layout, poses: Mapping[str, ObjectPose], index: int) -> PlacementCheck:
        """Whether subtask ``index``'s object sits at its goal given current ``poses``."""

    def check_index(self, index: int) -> None:
        if isinstance(index, bool) or not isinstance(index, int) or not 0 <= index < self.num_subtasks:
            raise ValueError(f"subtask: {self.name} has subtasks 0..{self.num_subtasks - 1}, got {index!r}")


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
