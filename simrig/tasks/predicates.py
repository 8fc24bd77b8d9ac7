"""The goal predicates of a task file, evaluated on object poses, and the pose each goal puts an object in.

The library (docs/tasks.md, "Goals"): ``in_region``, ``on_table``, ``on``, ``inside``, ``upright`` and their
conjunction ``all`` / disjunction ``any``. "Released" and "stable after release" hold for every subtask and
are checked by the simulator (``SimRobot.check_subtask``, with the subtask's ``settle``).

:func:`placement` names where a goal puts its object (a region, on a support, inside a container): the
simulator uses it to lay out the state after earlier subtasks, and the scripted skill to know where to
carry the object.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass

import numpy as np

from simrig.tasks.base import ObjectPose, PlacementCheck
from simrig.tasks.schema import InRegion, Inside, On, OnTable, Predicate, Region, Upright
from simrig.tasks.shapes import Geometry


@dataclass(frozen=True)
class Placement:
    """Where a goal puts an object: ``kind`` region | on | inside, and the region or object it names."""

    kind: str
    target: str
    tolerance: float  # horizontal, for on / inside; a region's own extent decides in_region


def placement(goal: Predicate, subject: str) -> Placement | None:
    """The first ``in_region`` / ``on`` / ``inside`` about ``subject`` in ``goal`` (depth first)."""
    kind = goal.kind
    if kind in ("all", "any"):
        for child in getattr(goal, kind):
            found = placement(child, subject)
            if found is not None:
                return found
        return None
    if kind == "in_region" and goal.in_region is not None and (goal.in_region.object or subject) == subject:
        return Placement("region", goal.in_region.region, 0.0)
    if kind == "on" and goal.on is not None and (goal.on.object or subject) == subject:
        return Placement("on", goal.on.support, goal.on.tolerance)
    if kind == "inside" and goal.inside is not None and (goal.inside.object or subject) == subject:
        return Placement("inside", goal.inside.container, goal.inside.tolerance)
    return None


def region_contains(region: Region, xy: np.ndarray, margin: float = 0.0) -> bool:
    dx, dy = float(xy[0]) - region.centre[0], float(xy[1]) - region.centre[1]
    if region.radius is not None:
        return math.hypot(dx, dy) <= region.radius - margin
    assert region.half_size is not None
    return abs(dx) <= region.half_size[0] - margin and abs(dy) <= region.half_size[1] - margin


class Evaluator:
    """Evaluates goals of one task on a mapping of object poses."""

    def __init__(self, geometry: Mapping[str, Geometry], regions: Mapping[str, Region]) -> None:
        self.geometry = geometry
        self.regions = regions

    def __call__(self, goal: Predicate, poses: Mapping[str, ObjectPose], subject: str) -> PlacementCheck:
        kind = goal.kind
        if kind == "all":
            assert goal.all is not None
            last = PlacementCheck(True, "")
            reasons = []
            for child in goal.all:
                last = self(child, poses, subject)
                if not last.in_place:
                    return last
                reasons.append(last.reason)
            return PlacementCheck(True, reasons[0] if reasons else "")
        if kind == "any":
            assert goal.any is not None
            results = [self(child, poses, subject) for child in goal.any]
            ok = [r for r in results if r.in_place]
            return ok[0] if ok else PlacementCheck(False, " and ".join(r.reason for r in results))
        check: PlacementCheck = getattr(self, f"_{kind}")(getattr(goal, kind), poses, subject)
        return check

    def _bottom_z(self, name: str, poses: Mapping[str, ObjectPose]) -> float:
        return float(poses[name].xyz[2]) - self.geometry[name].bottom

    def _in_region(self, p: InRegion, poses: Mapping[str, ObjectPose], subject: str) -> PlacementCheck:
        name = p.object or subject
        region = self.regions[p.region]
        xy = poses[name].position[:2]
        if not region_contains(region, xy):
            dist = math.hypot(float(xy[0]) - region.centre[0], float(xy[1]) - region.centre[1])
            return PlacementCheck(False, f"{name} is {dist * 100:.1f} cm from {p.region}")
        return PlacementCheck(True, f"{name} in {p.region}")

    def _on_table(self, p: OnTable, poses: Mapping[str, ObjectPose], subject: str) -> PlacementCheck:
        name = p.object or subject
        if abs(self._bottom_z(name, poses)) > p.height_tolerance:
            return PlacementCheck(False, f"{name} is not resting on the table")
        return PlacementCheck(True, f"{name} on the table")

    def _upright(self, p: Upright, poses: Mapping[str, ObjectPose], subject: str) -> PlacementCheck:
        name = p.object or subject
        tilt = poses[name].tilt()
        if tilt > math.radians(p.max_tilt_deg):
            return PlacementCheck(False, f"{name} is tilted {math.degrees(tilt):.0f}°")
        return PlacementCheck(True, f"{name} upright")

    def _on(self, p: On, poses: Mapping[str, ObjectPose], subject: str) -> PlacementCheck:
        name = p.object or subject
        a, b = poses[name].position, poses[p.support].position
        off = float(np.hypot(*(a[:2] - b[:2])))
        if off > p.tolerance:
            return PlacementCheck(False, f"{name} is {off * 100:.1f} cm off {p.support}")
        rest = self._bottom_z(p.support, poses) + self.geometry[p.support].height
        if abs(self._bottom_z(name, poses) - rest) > p.height_tolerance:
            return PlacementCheck(False, f"{name} is not resting on {p.support}")
        return PlacementCheck(True, f"{name} on {p.support}")

    def _inside(self, p: Inside, poses: Mapping[str, ObjectPose], subject: str) -> PlacementCheck:
        name = p.object or subject
        container = self.geometry[p.container].container
        assert container is not None  # the loader refuses inside goals on other shapes
        a, b = poses[name].position, poses[p.container].position
        off = float(np.hypot(*(a[:2] - b[:2])))
        if off > p.tolerance:
            return PlacementCheck(False, f"{name} is {off * 100:.1f} cm from {p.container}")
        seat = self._bottom_z(p.container, poses) + container.seat(self.geometry[name].base_radius)
        if abs(self._bottom_z(name, poses) - seat) > p.height_tolerance:
            return PlacementCheck(False, f"{name} is not resting inside {p.container}")
        return PlacementCheck(True, f"{name} inside {p.container}")
