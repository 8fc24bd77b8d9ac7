"""``pilworld bench paired-timing``: wall time per paired subtask, each branch separately, on the simulated rig.

Runs a short paired run into a temporary folder and reads its per-branch timings: seconds per
subtask, milliseconds per round for the policy query and for the environment step (the robot's K·Δ
control steps with rendering, or Γ plus one world-model call), and the realtime factor of each branch
(the subtask's robot time, R·K·Δ / control rate, over its wall time).
"""

from __future__ import annotations

import argparse
import json
import tempfile
import time
from pathlib import Path
from typing import Any

import numpy as np

from pilworld.bench.flags import add_json, add_rig
from pilworld.bench.output import emit
from pilworld.options.bounds import at_least_one
from pilworld.paired.runner import ORIGINS, TIMINGS_FILE, PairedConfig, paired_run
from pilworld.types import ChunkSpec


def _stats(values: list[float]) -> dict[str, float]:
    arr = np.asarray(values, dtype=np.float64)
    return {
        "median": round(float(np.median(arr)), 3),
        "p90": round(float(np.percentile(arr, 90)), 3),
        "mean": round(float(arr.mean()), 3),
    }


def bench_paired(
    *,
    rig: str,
    task: str = "sort_cubes",
    checkpoint: str = "",
    subtasks: int = 3,
    rounds: int = 5,
    world_model: str = "",
    progress: bool = False,
) -> dict[str, Any]:
    import torch

    from pilworld.config.rig import RigConfig
    from pilworld.policies.registry import default_checkpoint
    from simrig.tasks import make_task

    spec = ChunkSpec(rounds=rounds)
    control_rate = RigConfig.load(rig).control_rate_hz
    ckpt = checkpoint or default_checkpoint()
    t0 = time.monotonic()
    with tempfile.TemporaryDirectory(prefix="pilworld_bench_paired_") as tmp:
        out = Path(tmp) / "run"
        cfg = PairedConfig(
            rig=rig, task=task, checkpoints=[ckpt], subtasks=subtasks, out=str(out), world_model=world_model, spec=spec
        )
        paired_run(cfg, progress=progress)
        records = [json.loads(line) for line in (out / TIMINGS_FILE).read_text().splitlines()]
    robot_seconds = rounds * spec.executed_steps / control_rate
    result: dict[str, Any] = {
        "task": task,
        "instruction": make_task(task).instruction,
        "checkpoint": ckpt,
        "subtasks": subtasks,
        "rounds": rounds,
        "K": spec.frames,
        "stride": spec.stride,
        "robot_seconds_per_subtask": robot_seconds,
        "torch_threads": torch.get_num_threads(),
        "total_seconds": round(time.monotonic() - t0, 2),
    }
    for origin in ORIGINS:
        rows = [r for r in records if r["origin"] == origin]
        seconds = [float(r["seconds"]) for r in rows]
        result[origin] = {
            "seconds_per_subtask": _stats(seconds),
            "policy_ms_per_round": _stats([float(x) for r in rows for x in r["policy_ms"]]),
            "env_ms_per_round": _stats([float(x) for r in rows for x in r["env_ms"]]),
            "realtime_factor": round(robot_seconds / float(np.median(seconds)), 2),
        }
    return result


def add_arguments(parser: argparse.ArgumentParser) -> None:
    add_rig(parser)
    parser.add_argument("--task", default="sort_cubes", help="task (default sort_cubes)")
    parser.add_argument("--checkpoint", default="", help="policy checkpoint (default: the rig's best)")
    parser.add_argument("--subtasks", type=int, default=3, help="paired subtasks (default 3)")
    parser.add_argument("--rounds", type=int, default=5, help="closed-loop rounds per subtask (default 5)")
    parser.add_argument("--world-model", default="", help="world-model folder (default: the packaged checkpoint)")
    add_json(parser)


def run(args: argparse.Namespace) -> int:
    """One line per branch (real, imagined): seconds per subtask, policy and env per round, realtime factor."""
    at_least_one(args, "subtasks", "rounds")
    r = bench_paired(
        rig=str(args.rig),
        task=args.task,
        checkpoint=args.checkpoint,
        subtasks=args.subtasks,
        rounds=args.rounds,
        world_model=args.world_model,
        progress=not args.json,
    )
    lines = [
        f"paired {origin}: {b['seconds_per_subtask']['median']} s per subtask (median of {r['subtasks']}), "
        f"policy {b['policy_ms_per_round']['median']} ms and env {b['env_ms_per_round']['median']} ms per round, "
        f"realtime x{b['realtime_factor']}"
        for origin, b in ((o, r[o]) for o in ("real", "imagined"))
    ]
    return emit(args, r, lines)
