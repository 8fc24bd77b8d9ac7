"""Sort Cubes (paper appendix): three cubes of different sizes, smallest to largest into three slots.

Subtask ``k`` places the k-th smallest cube into slot ``k``, the next empty slot of the ordered row.
The slots are outlined on the far side of the table, left (+y, as the head camera sees it) to right.
"""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np

from hw_drivers.sim.objects import FixtureSpec, GeomSpec, ObjectSpec, box_object
from hw_drivers.sim.tasks.base import Layout, ObjectPose, PlacementCheck, Task, sample_positions

CUBES = (  # name, edge [m], rgba, mass [kg]
    ("cube_small", 0.035, (0.95, 0.80, 0.10, 1.0), 0.05),
    ("cube_medium", 0.045, (0.15, 0.70, 0.25, 1.0), 0.08),
    ("cube_large", 0.055, (0.50, 0.25, 0.75, 1.0), 0.12),
)
SLOT_X = 0.16
SLOT_YS = (0.13, 0.0, -0.13)
SLOT_HALF = 0.04  # half the outline's inner size [m]
SLOT_RGBA = (0.25, 0.25, 0.27, 1.0)
TOLERANCE = 0.03  # cube centre within this of the slot centre (x and y) [m]


class SortCubes(Task):
    name = "sort_cubes"
    instruction = "sort the cubes by size."
    num_subtasks = 3

    def objects(self) -> tuple[ObjectSpec, ...]:
        return tuple(box_object(n, (e / 2, e / 2, e / 2), rgba, m) for n, e, rgba, m in CUBES)

    def fixtures(self) -> tuple[FixtureSpec, ...]:
        bar = 0.004  # outline bar half-width; flat and non-colliding, so cubes rest on the table
        out = []
        for k, y in enumerate(SLOT_YS):
            h, t = SLOT_HALF + bar, 0.0006
            geoms = (
                GeomSpec("box", (h, bar, t), SLOT_RGBA, pos=(0.0, SLOT_HALF + bar, t), collide=False),
                GeomSpec("box", (h, bar, t), SLOT_RGBA, pos=(0.0, -SLOT_HALF - bar, t), collide=False),
                GeomSpec("box", (bar, h, t), SLOT_RGBA, pos=(SLOT_HALF + bar, 0.0, t), collide=False),
                GeomSpec("box", (bar, h, t), SLOT_RGBA, pos=(-SLOT_HALF - bar, 0.0, t), collide=False),
            )
            out.append(FixtureSpec(f"slot_{k}", geoms, pos=(SLOT_X, y, 0.0)))
        return tuple(out)

    def layout(self, seed: int) -> Layout:
        rng = np.random.default_rng([seed, 101])
        xy = sample_positions(rng, 3, x_range=(-0.12, 0.05), y_range=(-0.24, 0.24), min_distance=0.1)
        order = rng.permutation(3)
        poses = {}
        for (name, edge, _, _), k in zip(CUBES, order, strict=True):
            x, y = xy[k]
            poses[name] = ObjectPose.yawed(x, y, edge / 2, float(rng.uniform(-0.3, 0.3)))
        goals = {f"slot_{k}": (SLOT_X, y, 0.0) for k, y in enumerate(SLOT_YS)}
        return Layout(seed=seed, poses=poses, goals=goals)

    def subtask_object(self, index: int) -> str:
        self.check_index(index)
        return CUBES[index][0]

    def completed_poses(self, layout: Layout, done: int) -> dict[str, ObjectPose]:
        poses = dict(layout.poses)
        for k in range(done):
            name, edge = CUBES[k][0], CUBES[k][1]
            poses[name] = ObjectPose((SLOT_X, SLOT_YS[k], edge / 2))
        return poses

    def in_place(self, layout: Layout, poses: Mapping[str, ObjectPose], index: int) -> PlacementCheck:
        name, edge = CUBES[index][0], CUBES[index][1]
        p = poses[name].position
        dx, dy = p[0] - SLOT_X, p[1] - SLOT_YS[index]
        if max(abs(dx), abs(dy)) > TOLERANCE:
            return PlacementCheck(False, f"{name} is {np.hypot(dx, dy) * 100:.1f} cm from slot {index}")
        if abs(p[2] - edge / 2) > 0.006 or poses[name].tilt() > 0.2:
            return PlacementCheck(False, f"{name} is not resting flat on the table in slot {index}")
        return PlacementCheck(True, f"{name} in slot {index}")
