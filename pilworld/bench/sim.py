"""``pilworld bench sim``: physics and rendering speed of the simulated rig, and checkpoint success rates.

With ``--baseline LOOK`` the speed figures of a second appearance are measured alternately in the same
process and the ratios reported (``baseline_ratio``), the comparison that survives machine drift.

* ``physics_steps_per_s``: MuJoCo steps per wall second (arms tracking a command, objects resting);
* ``render_ms_per_view``: one 128×128 view rendered headless (mean over all cameras);
* ``realtime_factor``: simulated time / wall time for one subtask with the best checkpoint in closed
  loop and every Δ-th observation rendered (what data collection does), target ≥ 1;
* ``success_rates`` (with ``--subtasks N``): {task: {checkpoint: rate}} over N subtask starts.
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from pilworld.bench.flags import add_json, add_rig
from pilworld.bench.output import emit
from pilworld.collection.tasks import APPEARANCES
from pilworld.options.bounds import SIM_REPEATS, TRY_SUBTASKS, WORKERS, bounded, check_count
from pilworld.options.parse import parse_names
from pilworld.types import ChunkSpec

if TYPE_CHECKING:
    from simrig.tasks import Task


SPEED_KEYS = ("physics_steps_per_s", "render_ms_per_view", "realtime_factor", "subtask_wall_s")
REPEATS_MAX = 50


def measure_speed(rig_path: str, task: Task, appearance: str) -> dict[str, Any]:
    """One measurement of the speed figures of ``task``'s scene under ``appearance``."""
    from pilworld.collection.rollout import run_subtask
    from pilworld.policies.scripted import BEST_CHECKPOINT, ScriptedPolicy
    from simrig.gl import mujoco
    from simrig.robot import SimRobot

    spec = ChunkSpec()
    robot = SimRobot(rig_path, task, appearance=appearance)
    robot.connect()
    try:
        robot.reset(seed=0, subtask=0, history=0)
        model, data = robot._model, robot._data  # the bench times raw physics, below the Robot contract
        n = 5000
        t0 = time.perf_counter()
        for _ in range(n):
            mujoco.mj_step(model, data)
        physics = n / (time.perf_counter() - t0)
        views = robot.spec.cameras
        for v in views:
            robot.render(v)  # warm-up
        reps = 40
        t0 = time.perf_counter()
        for _ in range(reps):
            for v in views:
                robot.render(v)
        render_ms = (time.perf_counter() - t0) / (reps * len(views)) * 1000
        start = robot.reset(seed=1, subtask=0, history=0)
        policy = ScriptedPolicy(robot.rig, BEST_CHECKPOINT, seed=1, task=task)
        sim0, t0 = robot.time, time.perf_counter()
        run_subtask(robot, policy.infer, start.observation, robot.task.instruction, spec=spec, record=True)
        wall = time.perf_counter() - t0
        realtime = (robot.time - sim0) / wall
    finally:
        robot.disconnect()
    return {
        "physics_steps_per_s": round(physics, 1),
        "physics_timestep_s": float(model.opt.timestep),
        "render_ms_per_view": round(render_ms, 3),
        "image_size": list(robot.spec.image_size),
        "realtime_factor": round(realtime, 2),
        "subtask_wall_s": round(wall, 3),
    }


def _medians(runs: list[dict[str, Any]]) -> dict[str, Any]:
    out = dict(runs[0])
    for key in SPEED_KEYS:
        out[key] = round(float(np.median([r[key] for r in runs])), 3)
    return out


def run_sim_bench(
    rig_path: str,
    *,
    task: str | Task = "sort_cubes",
    subtasks: int = 0,
    tasks: list[str | Task] | None = None,
    checkpoints: list[str] | None = None,
    workers: int | None = None,
    progress: bool = True,
    appearance: str = "flat",
    repeats: int = 1,
    baseline: str | None = None,
) -> dict[str, Any]:
    """``task`` (a packaged name, a task file or a task) for the speed figures; ``tasks`` (default: the paper's
    three) for the success rates.

    The speed figures are the median of ``repeats`` measurements. With ``baseline`` (another appearance) the
    same figures are measured for it too, alternating with ``appearance`` in this one process, and their
    ratios reported: absolute speed differs between machines and drifts within a run, a ratio measured
    side by side does not (``baseline_ratio``: this look's figure over the baseline's).
    """
    from pilworld.collection.tasks import require_simulated, resolve_tasks
    from pilworld.policies.scripted import CHECKPOINTS
    from simrig.appearance import check_appearance
    from simrig.tasks import PAPER_TASKS

    check_appearance(appearance)
    if baseline is not None:
        check_appearance(baseline)
    if isinstance(repeats, bool) or not isinstance(repeats, int) or not 1 <= repeats <= REPEATS_MAX:
        raise ValueError(f"repeats: expected an integer in [1, {REPEATS_MAX}], got {repeats!r}")
    spec = ChunkSpec()
    (speed_task,) = resolve_tasks([task])
    rate_tasks = resolve_tasks(list(tasks or PAPER_TASKS)) if subtasks > 0 else []
    require_simulated([speed_task, *rate_tasks])
    runs: list[dict[str, Any]] = []
    base_runs: list[dict[str, Any]] = []
    for _ in range(repeats):
        if baseline is not None:
            base_runs.append(measure_speed(rig_path, speed_task, baseline))
        runs.append(measure_speed(rig_path, speed_task, appearance))
    result: dict[str, Any] = {
        "rig": Path(rig_path).name,
        "task": speed_task.name,
        "task_sha256": speed_task.digest,
        "appearance": appearance,
        **_medians(runs),
        "repeats": repeats,
    }
    if baseline is not None:
        base = _medians(base_runs)
        result["baseline"] = {"appearance": baseline, **{k: base[k] for k in SPEED_KEYS}}
        # Per repeat (the two measured back to back), then the median: drift between repeats cancels.
        result["baseline_ratio"] = {
            k: round(float(np.median([r[k] / b[k] for r, b in zip(runs, base_runs, strict=True)])), 3)
            for k in ("render_ms_per_view", "realtime_factor")
        }
    if subtasks > 0:
        from pilworld.collection.evaluate import success_rates

        names = [t.name for t in rate_tasks]
        ckpts = checkpoints or [c.name for c in CHECKPOINTS]
        t0 = time.perf_counter()
        rates = success_rates(
            rig_path,
            list(rate_tasks),
            ckpts,
            subtasks,
            workers=workers,
            spec=spec,
            progress=progress,
            appearance=appearance,
        )
        result["success_rates"] = rates
        result["subtasks"] = subtasks
        result["success_rates_wall_s"] = round(time.perf_counter() - t0, 1)
        result["spread_ok"] = all(max(r.values()) >= 0.9 and min(r.values()) <= 0.4 for r in rates.values())
        result["mean_by_checkpoint"] = {c: round(float(np.mean([rates[t][c] for t in names])), 3) for c in ckpts}
    return result


def add_arguments(parser: argparse.ArgumentParser) -> None:
    add_rig(parser)
    parser.add_argument(
        "--task", default="sort_cubes", help="task (name or task file) for the speed figures (default sort_cubes)"
    )
    parser.add_argument(
        "--subtasks",
        type=int,
        default=None,
        help="also measure success rates over N subtask starts per task [1..1,000] (default: speed figures only)",
    )
    parser.add_argument(
        "--tasks",
        default="all",
        help="tasks for the success rates: names or task files, comma-separated, or all (the paper's three; default)",
    )
    parser.add_argument("--appearance", default="flat", choices=APPEARANCES, help="scene appearance (default flat)")
    parser.add_argument(
        "--baseline",
        default=None,
        choices=APPEARANCES,
        help="also time this appearance, alternating with --appearance, and report their ratios (default: none)",
    )
    parser.add_argument(
        "--repeats",
        type=int,
        default=1,
        help=bounded("speed measurements per appearance; medians reported (default 1)", SIM_REPEATS),
    )
    parser.add_argument("--checkpoints", default="all", help="comma-separated scripted checkpoints (default all)")
    parser.add_argument(
        "--workers", type=int, default=None, help="processes for the success rates (default: CPUs) [1..256]"
    )
    add_json(parser)


def run(args: argparse.Namespace) -> int:
    """Every flag checked before the rig starts, then the speed figures (and success rates) in a few lines."""
    from pilworld.collection.tasks import require_simulated, resolve_tasks
    from pilworld.policies.scripted import CHECKPOINTS

    check_count(args.subtasks, "--subtasks", TRY_SUBTASKS)
    check_count(args.workers, "--workers", WORKERS)
    check_count(args.repeats, "--repeats", SIM_REPEATS)
    (task,) = resolve_tasks([args.task], what="--task")
    tasks = resolve_tasks(args.tasks, what="--tasks")
    require_simulated([task], what="--task")
    require_simulated(tasks, what="--tasks")
    ckpts = parse_names(args.checkpoints, [c.name for c in CHECKPOINTS], "--checkpoints")
    result = run_sim_bench(
        str(args.rig),
        task=task,
        subtasks=args.subtasks or 0,
        tasks=list(tasks),
        appearance=args.appearance,
        checkpoints=ckpts,
        workers=args.workers,
        progress=not args.json,
        repeats=args.repeats,
        baseline=args.baseline,
    )
    return emit(args, result, summary_lines(result, args.appearance, args.repeats))


def summary_lines(result: dict[str, Any], appearance: str, repeats: int) -> list[str]:
    """Speed, the baseline's ratios when one was timed, and the success rates per task."""
    lines = [
        f"sim ({appearance}): {result['physics_steps_per_s']:.0f} physics steps/s, "
        f"{result['render_ms_per_view']:.1f} ms per view, realtime factor {result['realtime_factor']:.1f}"
    ]
    if "baseline" in result:
        b, r = result["baseline"], result["baseline_ratio"]
        lines.append(
            f"  {b['appearance']}: {b['render_ms_per_view']:.1f} ms per view, realtime factor "
            f"{b['realtime_factor']:.1f}; {appearance} / {b['appearance']}: "
            f"render ×{r['render_ms_per_view']:.2f}, "
            f"realtime ×{r['realtime_factor']:.2f} (median of {repeats}, measured side by side)"
        )
    for task, rates in result.get("success_rates", {}).items():
        lines.append(f"  {task}: " + ", ".join(f"{c} {r:.2f}" for c, r in rates.items()))
    return lines
