"""The scripted skill on task files beyond the paper's: every packaged task is solved by the best checkpoint
from a few starts (a cylinder, a sphere into a cup, a compound mug, a lying cylinder into a tray, a mesh
into a bowl), and a pinched object goes into a container narrower than the open fingers from above its rim."""

from __future__ import annotations

from collections.abc import Callable

import pytest

from pilworld.collection.rollout import run_subtask
from pilworld.policies.scripted import BEST_CHECKPOINT, ScriptedPolicy
from pilworld.policies.scripted.knowledge import knowledge_for
from pilworld.types import ChunkSpec
from simrig.robot import SimRobot
from simrig.tasks import PAPER_TASKS, load_task, packaged_tasks

NEW_TASKS = tuple(n for n in packaged_tasks() if n not in PAPER_TASKS)


@pytest.mark.parametrize("name", NEW_TASKS)
def test_the_best_checkpoint_solves_the_new_tasks(robots: Callable[[str], SimRobot], name: str) -> None:
    robot = robots(name)
    spec = ChunkSpec()
    n = robot.task.num_subtasks
    for seed in (0, 1):  # start i: subtask i mod n of layout seed i, as the benchmarks start them
        subtask = seed % n
        policy = ScriptedPolicy(robot.rig, BEST_CHECKPOINT, seed=seed * 100 + subtask, task=robot.task)
        start = robot.reset(seed=seed, subtask=subtask, history=spec.history, stride=spec.stride)
        rec = run_subtask(
            robot,
            policy.infer,
            start.observation,
            robot.task.instruction,
            spec=spec,
            record=False,
            subtask_index=subtask,
        )
        assert rec.check is not None and rec.check.success, f"{name} seed {seed}: {rec.check}"


def test_fingers_open_inside_only_containers_wide_enough(robots: Callable[[str], SimRobot]) -> None:
    policy = ScriptedPolicy(robots("sort_cubes").rig)
    cup, bowl = knowledge_for("ball_in_cup"), knowledge_for("nut_in_bowl")
    assert not policy._fingers_fit("left", cup, "cup")  # a 72 mm cup: let go above its rim
    assert policy._fingers_fit("right", bowl, "bowl")  # a 150 mm bowl: set down on its floor
    assert not policy._fingers_fit("left", bowl, "nut")  # not a container at all


def test_new_tasks_name_their_instructions_uniquely() -> None:
    """A policy without a task file recognises a packaged task by its instruction."""
    from pilworld.policies.scripted.knowledge import knowledge_for_instruction

    for name in NEW_TASKS:
        assert knowledge_for_instruction(load_task(name).instruction.upper()).task.name == name
