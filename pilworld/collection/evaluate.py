"""Success rates of scripted checkpoints on the simulated rig (the real branch alone, judged by the checker).

Evaluation unit = one subtask start: ``N`` starts per task cycle through the subtasks with seeds
``seed0, seed0 + 1, …`` (start ``i`` is subtask ``i mod n`` of layout ``seed0 + i``), exactly as the
paired runner starts them, and every checkpoint sees the same starts.
"""

from __future__ import annotations

from collections.abc import Sequence

from tqdm import tqdm

from pilworld.collection.workers import process_map, worker_count, worker_robot
from pilworld.types import ChunkSpec


def _evaluate_one(args: tuple[str, str, str, int, int, ChunkSpec]) -> tuple[str, str, int, bool]:
    rig_path, task, checkpoint, seed, subtask, spec = args
    from pilworld.collection.rollout import run_subtask
    from pilworld.policies.scripted import ScriptedPolicy

    robot = worker_robot(rig_path, task)
    policy = ScriptedPolicy(robot.rig, checkpoint, seed=seed * 100 + subtask, horizon=spec.horizon)
    start = robot.reset(seed=seed, subtask=subtask, history=spec.history, stride=spec.stride)
    rec = run_subtask(
        robot, policy.infer, start.observation, robot.task.instruction, spec=spec, record=False, subtask_index=subtask
    )
    assert rec.check is not None
    return task, checkpoint, seed, rec.check.success


def success_rates(
    rig_path: str,
    tasks: Sequence[str],
    checkpoints: Sequence[str],
    subtasks: int,
    *,
    seed0: int = 0,
    workers: int | None = None,
    spec: ChunkSpec | None = None,
    progress: bool = True,
) -> dict[str, dict[str, float]]:
    """{task: {checkpoint: success rate over ``subtasks`` starts}}."""
    from simrig.tasks import make_task

    if subtasks < 1:
        raise ValueError(f"subtasks: expected at least 1, got {subtasks}")
    spec = spec or ChunkSpec()
    jobs = []
    for task in tasks:
        n = make_task(task).num_subtasks
        for ckpt in checkpoints:
            jobs += [(rig_path, task, ckpt, seed0 + i, i % n, spec) for i in range(subtasks)]
    wins: dict[str, dict[str, int]] = {t: {c: 0 for c in checkpoints} for t in tasks}
    workers = worker_count(workers, len(jobs))
    with tqdm(total=len(jobs), desc="subtasks", unit="subtask", disable=not progress) as bar:
        for task, ckpt, _, ok in process_map(_evaluate_one, jobs, workers, ordered=False, chunksize=4):
            wins[task][ckpt] += int(ok)
            bar.update(1)
    return {t: {c: wins[t][c] / subtasks for c in checkpoints} for t in tasks}
