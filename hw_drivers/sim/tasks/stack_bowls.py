"""Stack Bowls (paper appendix): three bowls into a stable nested stack at the stacking location.

Subtask 0 puts the large bowl on the marked stacking location, subtask 1 the medium bowl into it and
subtask 2 the small bowl into the medium one. Bowls are built from convex pieces (see ``objects.py``).
"""

from __future__ import annotations

import math
from collections.abc import Mapping

import numpy as np

from hw_drivers.sim.objects import FixtureSpec, GeomSpec, ObjectSpec, bowl_object
from hw_drivers.sim.tasks.base import Layout, ObjectPose, PlacementCheck, Task, sample_positions

BOWLS = (  # name, bottom radius, top radius, height [m], rgba, mass [kg]
    ("bowl_large", 0.045, 0.068, 0.045, (0.95, 0.45, 0.10, 1.0), 0.12),
    ("bowl_medium", 0.032, 0.055, 0.040, (0.10, 0.70, 0.80, 1.0), 0.09),
    ("bowl_small", 0.020, 0.042, 0.035, (0.90, 0.30, 0.60, 1.0), 0.07),
)
WALL = 0.006
LIP = 0.015  # the vertical rim band a gripper pinches
STACK_XY = (0.15, 0.0)
MARK_RGBA = (0.25, 0.25, 0.27, 1.0)
TOLERANCE = 0.02  # horizontal offset of a bowl from its target centre [m]


def nested_base_height(index: int) -> float:
    """Height of bowl ``index``'s underside when nested in the stack (resting on the bowl below)."""
    if index == 0:
        return 0.0
    # A bowl rests where its base disc meets the flaring inner wall of the one below, or on its floor.
    below = BOWLS[index - 1]
    r_in0 = below[1] - WALL  # inner radius of the wall at the floor, roughly
    slope = (below[2] - below[1]) / (below[3] - LIP)
    r_base = BOWLS[index][1]
    rise = max(0.0, (r_base - r_in0) / slope)
    return nested_base_height(index - 1) + WALL + rise


class StackBowls(Task):
    name = "stack_bowls"
    instruction = "pick up the bowls and stack them one by one."
    num_subtasks = 3

    def objects(self) -> tuple[ObjectSpec, ...]:
        return tuple(
            bowl_object(
                n, bottom_radius=rb, top_radius=rt, height=h, rgba=rgba, mass=m, wall=WALL, lip=LIP, friction=0.6
            )
            for n, rb, rt, h, rgba, m in BOWLS
        )

    def fixtures(self) -> tuple[FixtureSpec, ...]:
        # A flat ring marks the stacking location (visual only).
        r, n = 0.075, 16
        geoms = []
        for i in range(n):
            phi = 2 * math.pi * i / n
            quat = (math.cos(phi / 2), 0.0, 0.0, math.sin(phi / 2))
            geoms.append(
                GeomSpec(
                    "box",
                    (0.004, math.pi * r / n, 0.0006),
                    MARK_RGBA,
                    pos=(r * math.cos(phi), r * math.sin(phi), 0.0006),
                    quat=quat,
                    collide=False,
                )
            )
        return (FixtureSpec("stack_mark", tuple(geoms), pos=(*STACK_XY, 0.0)),)

    def layout(self, seed: int) -> Layout:
        rng = np.random.default_rng([seed, 202])
        keep_out = ((STACK_XY[0], STACK_XY[1], 0.15),)
        xy = sample_positions(rng, 3, x_range=(-0.1, 0.06), y_range=(-0.22, 0.22), min_distance=0.14, keep_out=keep_out)
        order = rng.permutation(3)
        poses = {
            name: ObjectPose.yawed(xy[k][0], xy[k][1], 0.0, float(rng.uniform(-math.pi, math.pi)))
            for (name, *_), k in zip(BOWLS, order, strict=True)
        }
        return Layout(seed=seed, poses=poses, goals={"stack": (*STACK_XY, 0.0)})

    def subtask_object(self, index: int) -> str:
        self.check_index(index)
        return BOWLS[index][0]

    def completed_poses(self, layout: Layout, done: int) -> dict[str, ObjectPose]:
        poses = dict(layout.poses)
        for k in range(done):
            poses[BOWLS[k][0]] = ObjectPose((*STACK_XY, nested_base_height(k) + 0.001))
        return poses

    def in_place(self, layout: Layout, poses: Mapping[str, ObjectPose], index: int) -> PlacementCheck:
        name = BOWLS[index][0]
        p = poses[name].position
        target = np.array(STACK_XY) if index == 0 else poses[BOWLS[index - 1][0]].position[:2]
        off = float(np.hypot(*(p[:2] - target)))
        where = "the stacking location" if index == 0 else BOWLS[index - 1][0]
        if off > TOLERANCE:
            return PlacementCheck(False, f"{name} is {off * 100:.1f} cm from {where}")
        base = 0.0 if index == 0 else poses[BOWLS[index - 1][0]].position[2]
        expected = nested_base_height(index) - nested_base_height(index - 1) if index else 0.0
        if abs(p[2] - base - expected) > 0.012 or poses[name].tilt() > 0.25:
            return PlacementCheck(False, f"{name} is not nested level in {where}")
        return PlacementCheck(True, f"{name} nested on {where}")
