"""What the hand-written image-only judge knows about the paper's three tasks: read from their task files.

The reference judge of the paper's tasks (cubes and bowls only): object colours and sizes, where the
slots and the stacking mark are, and what each subtask asks for, read through :func:`simrig.tasks.load_task`
from ``configs/tasks/`` — as a person judging the videos would know them from the task description.
Nothing here depends on a seed or a layout. It reads task files, which a judge may not: it stays only as
the named reference for the paper's tasks until the learned judges replace it.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass

from pilworld.perception.colour import ColourClass
from pilworld.perception.silhouette import BowlShape, BoxShape, Shape
from simrig.tasks import PAPER_TASKS, Task, load_task
from simrig.tasks import schema as s


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


def _shape(task: Task, name: str) -> Shape:
    obj = next(o for o in task.spec.objects if o.name == name)
    if isinstance(obj, s.BoxObject) and len(set(obj.size)) == 1:
        return BoxShape(obj.size[0])
    if isinstance(obj, s.BowlObject):
        return BowlShape(obj.bottom_radius, obj.top_radius, obj.height, obj.wall, obj.lip)
    raise ValueError(f"the image-only judge models cubes and bowls only; {name} of task {task.name!r} is a {obj.shape}")


def _from_file(task: Task) -> TaskSpec:
    """The judge's prior of a paper task, read from its task file (the chains of goals, their heights)."""
    objects = tuple(SceneObject(ColourClass(n, task.colour(n)), _shape(task, n)) for n in task.object_names)
    heights = task.done_heights()
    moved = [task.subtask_object(k) for k in range(task.num_subtasks)]
    goals = []
    for k, name in enumerate(moved):
        where = task.goal_placement(k)
        assert where is not None
        # What may come to stand on this goal's target once stacked: the later subtasks' objects.
        above = tuple(moved[k + 1 :])
        if where.kind == "region":
            region = task.regions[where.target]
            square = region.half_size is not None
            tol = region.half_size[0] if region.half_size is not None else float(region.radius or 0.0)
            later = (task.goal_placement(j) for j in range(k + 1, len(moved)))
            chained = any(p is not None and p.target == name for p in later)
            goals.append(
                SubtaskGoal(
                    k, name, heights[name], tol, goal_xy=region.centre, square=square, above=above if chained else ()
                )
            )
        else:
            goals.append(
                SubtaskGoal(
                    k,
                    name,
                    heights[name],
                    where.tolerance,
                    reference=where.target,
                    reference_z=heights[where.target],
                    above=above,
                )
            )
    return TaskSpec(task.name, task.instruction, objects, tuple(goals))


TASK_SPECS: Mapping[str, TaskSpec] = {n: _from_file(load_task(n)) for n in PAPER_TASKS}


def task_spec(task: str, instruction: str = "") -> TaskSpec:
    """The paper task named ``task`` (the episode's task name), or else the one whose instruction this is."""
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
