"""Stack Blocks (paper appendix): three blocks; the second onto the first, the third onto the pair.

The first block stays where the layout puts it. Success needs the tower to stay standing after the
gripper lets go, which the simulator checks for every task (``SimRobot.check_subtask``).
"""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np

from hw_drivers.sim.objects import ObjectSpec, box_object
from hw_drivers.sim.tasks.base import Layout, ObjectPose, PlacementCheck, Task, sample_positions

BLOCK = 0.04  # edge [m]
BLOCKS = (  # name, rgba
    ("block_red", (0.90, 0.20, 0.20, 1.0)),
    ("block_sky", (0.20, 0.60, 0.90, 1.0)),
    ("block_green", (0.30, 0.75, 0.30, 1.0)),
)
TOLERANCE = 0.015  # horizontal offset from the block below [m]


class StackBlocks(Task):
    name = "stack_blocks"
    instruction = "pick up the blocks and stack them one by one."
    num_subtasks = 2

    def objects(self) -> tuple[ObjectSpec, ...]:
        h = BLOCK / 2
        return tuple(box_object(n, (h, h, h), rgba, 0.06, friction=0.9) for n, rgba in BLOCKS)

    def layout(self, seed: int) -> Layout:
        rng = np.random.default_rng([seed, 303])
        xy = sample_positions(rng, 3, x_range=(-0.1, 0.12), y_range=(-0.22, 0.22), min_distance=0.11)
        poses = {
            name: ObjectPose.yawed(*xy[k], BLOCK / 2, float(rng.uniform(-0.3, 0.3)))
            for k, (name, _) in enumerate(BLOCKS)
        }
        return Layout(seed=seed, poses=poses, goals={})

    def subtask_object(self, index: int) -> str:
        self.check_index(index)
        return BLOCKS[index + 1][0]

    def completed_poses(self, layout: Layout, done: int) -> dict[str, ObjectPose]:
        poses = dict(layout.poses)
        base = layout.poses[BLOCKS[0][0]]
        for k in range(done):
            x, y, _ = base.xyz
            poses[BLOCKS[k + 1][0]] = ObjectPose((x, y, BLOCK / 2 + (k + 1) * BLOCK), base.quat)
        return poses

    def in_place(self, layout: Layout, poses: Mapping[str, ObjectPose], index: int) -> PlacementCheck:
        name, below = BLOCKS[index + 1][0], BLOCKS[index][0]
        p, q = poses[name].position, poses[below].position
        off = float(np.hypot(*(p[:2] - q[:2])))
        if off > TOLERANCE:
            return PlacementCheck(False, f"{name} is {off * 100:.1f} cm off {below}")
        if abs(p[2] - (BLOCK / 2 + (index + 1) * BLOCK)) > 0.006 or poses[name].tilt() > 0.15:
            return PlacementCheck(False, f"{name} is not standing level on the tower")
        return PlacementCheck(True, f"{name} stacked on {below}")
