"""What the image-only judge knows about each simulated task: fixed task knowledge, no simulator state.

The same prior the scripted policies use (:mod:`pilworld.policies.scripted.knowledge`): object colours
and sizes, where the slots and the stacking mark are, and what each subtask asks for — written down
from the task definitions in ``hw_drivers.sim.tasks``, as a person judging the videos would know them
from the task description. Nothing here depends on a seed or a layout.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass

from hw_drivers.sim.tasks import sort_cubes as sc
from hw_drivers.sim.tasks import stack_blocks as sb
from hw_drivers.sim.tasks import stack_bowls as sw
from pilworld.judges.vision_fit import BowlShape, BoxShape, Shape
from pilworld.perception.colour import ColourClass
from pilworld.policies.scripted.knowledge import KNOWLEDGE


@dataclass(frozen=True)
class SceneObject:
    """One task object: its colour class and its shape."""

    colour: ColourClass
    shape: Shape

    @property
    def name(self) -> str:
        return self.colour.name


@dataclass(frozen=True)
class SubtaskGoal:
    """Subtask ``index`` of a task: which object goes where, and how close counts as "in place".

    The goal is a fixed point (``goal_xy``: a slot, the stacking mark) or another object
    (``reference``: the block or bowl below). ``target_z`` / ``reference_z`` are the undersides' heights
    when in place [m]. ``square`` compares ``max(|dx|, |dy|)`` with ``tolerance`` (the slots), else the
    distance. ``above`` lists objects that may stand on the target or the reference once stacked (they
    may hide them; their pixels carry no evidence about what is below).
    """

    index: int
    target: str
    target_z: float
    tolerance: float
    goal_xy: tuple[float, float] | None = None
    reference: str | None = None
    reference_z: float = 0.0
    square: bool = False
    above: tuple[str, ...] = ()


@dataclass(frozen=True)
class TaskSpec:
    """A simulated task as the judge knows it."""

    name: str
    instruction: str
    objects: tuple[SceneObject, ...]
    goals: tuple[SubtaskGoal, ...]

    @property
    def classes(self) -> list[ColourClass]:
        return [o.colour for o in self.objects]

    def object(self, name: str) -> SceneObject:
        for o in self.objects:
            if o.name == name:
                return o
        raise KeyError(name)

    def goal(self, index: int) -> SubtaskGoal:
        if isinstance(index, bool) or not isinstance(index, int) or not 0 <= index < len(self.goals):
            raise ValueError(f"subtask_index: {self.name} has subtasks 0..{len(self.goals) - 1}, got {index!r}")
        return self.goals[index]


def _classes(task: str) -> dict[str, ColourClass]:
    return {c.name: c for c in KNOWLEDGE[task]().classes}


def _sort_cubes() -> TaskSpec:
    colours = _classes(sc.SortCubes.name)
    objects = tuple(SceneObject(colours[name], BoxShape(edge)) for name, edge, _, _ in sc.CUBES)
    goals = tuple(
        SubtaskGoal(k, name, 0.0, sc.TOLERANCE, goal_xy=(sc.SLOT_X, sc.SLOT_YS[k]), square=True)
        for k, (name, _, _, _) in enumerate(sc.CUBES)
    )
    return TaskSpec(sc.SortCubes.name, sc.SortCubes.instruction, objects, goals)


def _stack_bowls() -> TaskSpec:
    colours = _classes(sw.StackBowls.name)
    objects = tuple(
        SceneObject(colours[name], BowlShape(rb, rt, h, sw.WALL, sw.LIP)) for name, rb, rt, h, _, _ in sw.BOWLS
    )
    names = [b[0] for b in sw.BOWLS]
    goals = []
    for k, name in enumerate(names):
        z = sw.nested_base_height(k)
        if k == 0:
            goals.append(SubtaskGoal(k, name, z, sw.TOLERANCE, goal_xy=sw.STACK_XY, above=tuple(names[1:])))
        else:
            goals.append(
                SubtaskGoal(
                    k,
                    name,
                    z,
                    sw.TOLERANCE,
                    reference=names[k - 1],
                    reference_z=sw.nested_base_height(k - 1),
                    above=tuple(names[k + 1 :]),
                )
            )
    return TaskSpec(sw.StackBowls.name, sw.StackBowls.instruction, objects, tuple(goals))


def _stack_blocks() -> TaskSpec:
    colours = _classes(sb.StackBlocks.name)
    objects = tuple(SceneObject(colours[name], BoxShape(sb.BLOCK)) for name, _ in sb.BLOCKS)
    names = [b[0] for b in sb.BLOCKS]
    goals = tuple(
        SubtaskGoal(
            k,
            names[k + 1],
            (k + 1) * sb.BLOCK,
            sb.TOLERANCE,
            reference=names[k],
            reference_z=k * sb.BLOCK,
            above=tuple(names[k + 2 :]),
        )
        for k in range(sb.StackBlocks.num_subtasks)
    )
    return TaskSpec(sb.StackBlocks.name, sb.StackBlocks.instruction, objects, goals)


TASK_SPECS: Mapping[str, TaskSpec] = {t.name: t for t in (_sort_cubes(), _stack_bowls(), _stack_blocks())}


def task_spec(task: str, instruction: str = "") -> TaskSpec:
    """The task named ``task`` (``extra.sim_task``), or else the one whose instruction this is."""
    if task in TASK_SPECS:
        return TASK_SPECS[task]
    want = instruction.strip().lower()
    for spec in TASK_SPECS.values():
        if want and spec.instruction.strip().lower() == want:
            return spec
    raise ValueError(
        f"task: the image-only judge knows {', '.join(TASK_SPECS)} (or their instructions); "
        f"got task {task!r} with instruction {instruction!r}"
    )
