"""Success rates of scripted checkpoints on the simulated rig (the real branch alone, judged by the checker).

Evaluation unit = one subtask start: ``N`` starts per task cycle through the subtasks with seeds
``seed0, seed0 + 1, …`` (start ``i`` is subtask ``i mod n`` of layout ``seed0 + i``), exactly as the
paired runner starts them, and every checkpoint sees the same starts.
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path
from typing import TYPE_CHECKING

from tqdm import tqdm

from pilworld.collection.workers import process_map, worker_count, worker_robot
from pilworld.types import ChunkSpec

if TYPE_CHECKING:
    from simrig.tasks import Task


Job = tuple[str, "str | Task", str, int, int, ChunkSpec, str]


def _evaluate_one(args: Job) -> tuple[str, str, int, bool]:
    rig_path, task, checkpoint, seed, subtask, spec, appearance = args
    from pilworld.collection.rollout import run_subtask
    from pilworld.policies.scripted import ScriptedPolicy

    robot = worker_robot(rig_path, task, appearance)
    # Given its task file, a scripted checkpoint acts on that task whatever the instruction says.
    policy = ScriptedPolicy(robot.rig, checkpoint, seed=seed * 100 + subtask, horizon=spec.horizon, task=robot.task)
    start = robot.reset(seed=seed, subtask=subtask, history=spec.history, stride=spec.stride)
    rec = run_subtask(
        robot, policy.infer, start.observation, robot.task.instruction, spec=spec, record=False, subtask_index=subtask
    )
    assert rec.check is not None
    return robot.task.name, checkpoint, seed, rec.check.success


def success_rates(
    rig_path: str,
    tasks: Sequence[str | Path | Task],
    checkpoints: Sequence[str],
    subtasks: int,
    *,
    seed0: int = 0,
    workers: int | None = None,
    spec: ChunkSpec | None = None,
    progress: bool = True,
    appearance: str = "flat",
) -> dict[str, dict[str, float]]:
    """{task name: {checkpoint: success rate over ``subtasks`` starts}}; ``tasks`` are names, paths or tasks."""
    from pilworld.collection.tasks import require_simulated, resolve_tasks, task_ref

    if subtasks < 1:
        raise ValueError(f"subtasks: expected at least 1, got {subtasks}")
    loaded = resolve_tasks(list(tasks))
    require_simulated(loaded)
    spec = spec or ChunkSpec()
    jobs: list[Job] = []
    for task in loaded:
        n = task.num_subtasks
        for ckpt in checkpoints:
            jobs += [(rig_path, task_ref(task), ckpt, seed0 + i, i % n, spec, appearance) for i in range(subtasks)]
    wins: dict[str, dict[str, int]] = {t.name: {c: 0 for c in checkpoints} for t in loaded}
    workers = worker_count(workers, len(jobs))
    with tqdm(total=len(jobs), desc="subtasks", unit="subtask", disable=not progress) as bar:
        for name, ckpt, _, ok in process_map(_evaluate_one, jobs, workers, ordered=False, chunksize=4):
            wins[name][ckpt] += int(ok)
            bar.update(1)
    return {t.name: {c: wins[t.name][c] / subtasks for c in checkpoints} for t in loaded}
