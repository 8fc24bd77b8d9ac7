"""The simulated rig's tasks (paper appendix), registered by name."""

from __future__ import annotations

from hw_drivers.sim.tasks.base import Layout, ObjectPose, PlacementCheck, Task
from hw_drivers.sim.tasks.sort_cubes import SortCubes
from hw_drivers.sim.tasks.stack_blocks import StackBlocks
from hw_drivers.sim.tasks.stack_bowls import StackBowls

TASKS: dict[str, type[Task]] = {t.name: t for t in (SortCubes, StackBowls, StackBlocks)}
TASK_NAMES = tuple(TASKS)


def make_task(name: str) -> Task:
    """The task registered as ``name``; ``ValueError`` lists the valid names."""
    try:
        return TASKS[name]()
    except KeyError:
        raise ValueError(f"task: unknown task {name!r}; choose one of {', '.join(TASK_NAMES)}") from None


__all__ = ["TASKS", "TASK_NAMES", "Layout", "ObjectPose", "PlacementCheck", "Task", "make_task"]
