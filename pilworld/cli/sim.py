"""``pilworld sim collect|show``: data collection on the simulated rig and a quick look at a task.

``collect`` records runs of scripted checkpoints into an episode store (see
:mod:`pilworld.collection.collect` for what is stored at which rate); ``show`` writes the three
camera views of a task's start side by side into a PNG.
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path
from typing import Any

from pilworld.collection.tasks import APPEARANCES
from pilworld.options.bounds import EPISODES, SCALE, SEED, SUBTASK_INDEX, WORKERS, bounded, check_count
from pilworld.options.parse import parse_names
from simrig.files import SIM_RIG


def register(sub: Any) -> None:
    p: argparse.ArgumentParser = sub.add_parser("sim", help="the simulated rig: collect data, show a task")
    cmds = p.add_subparsers(dest="sim_command", metavar="COMMAND")
    cmds.required = True

    c = cmds.add_parser("collect", help="record runs of scripted checkpoints into an episode store")
    c.add_argument(
        "--task",
        default="all",
        help="task(s): packaged names or task files (.yaml), comma-separated, or 'all' (the paper's three; default)",
    )
    c.add_argument(
        "--instruction", default=None, help="the instruction given to the policy and recorded (default: the task's)"
    )
    c.add_argument("--appearance", default="flat", choices=APPEARANCES, help="scene appearance (default flat)")
    c.add_argument("--checkpoint", default="all", help="scripted checkpoint(s), comma-separated, or 'all'")
    c.add_argument("--episodes", type=int, required=True, help=bounded("runs per task and checkpoint", EPISODES))
    c.add_argument("--out", type=Path, required=True, help="dataset folder (created or resumed)")
    c.add_argument("--rig", type=Path, default=SIM_RIG, help="rig config (default: the simulated rig)")
    c.add_argument("--seed", type=int, default=0, help=bounded("layout seed of the first run (default 0)", SEED))
    c.add_argument("--workers", type=int, default=None, help=bounded("processes (default: CPUs)", WORKERS))
    c.add_argument("--video-mode", default="h264", choices=["h264", "lossless", "av1"])
    c.add_argument("--json", action="store_true", help="print the summary as one JSON object on the last line")
    c.set_defaults(handler=_collect)

    s = cmds.add_parser("show", help="write the three views of a task start side by side (PNG)")
    s.add_argument("--task", required=True, help="a packaged task's name or a task file (.yaml)")
    s.add_argument("--seed", type=int, default=0, help="layout seed (default 0)")
    s.add_argument("--subtask", type=int, default=0, help="subtask whose start to show (default 0)")
    s.add_argument("--out", type=Path, required=True, help="PNG file to write")
    s.add_argument("--rig", type=Path, default=SIM_RIG, help="rig config (default: the simulated rig)")
    s.add_argument("--scale", type=int, default=2, help="integer upscaling of the image (default 2)")
    s.set_defaults(handler=_show)


def _collect(args: argparse.Namespace) -> int:
    from pilworld.collection.collect import collect
    from pilworld.collection.tasks import check_instruction, require_simulated, resolve_tasks
    from pilworld.policies.scripted import CHECKPOINTS

    check_count(args.episodes, "--episodes", EPISODES)
    check_count(args.workers, "--workers", WORKERS)
    check_count(args.seed, "--seed", SEED)
    tasks = resolve_tasks(args.task, what="--task")
    require_simulated(tasks, what="--task")
    instruction = check_instruction(args.instruction, "--instruction")
    ckpts = parse_names(args.checkpoint, [c.name for c in CHECKPOINTS], "--checkpoint")
    summary = collect(
        args.out,
        rig_path=str(args.rig),
        tasks=tasks,
        instruction=instruction,
        appearance=args.appearance,
        checkpoints=ckpts,
        episodes=args.episodes,
        seed0=args.seed,
        workers=args.workers,
        video_mode=args.video_mode,
        progress=not args.json,
    )
    print(
        f"sim collect: {summary['episodes']} subtask episodes ({summary['frames']} frames, "
        f"{summary['bytes'] / 1e6:.1f} MB) in {summary['root']}: {summary['success']} successes, "
        f"{summary['failure']} failures; {summary['runs_simulated']} runs simulated in {summary['seconds']} s"
    )
    for task, rows in summary["per_task"].items():
        print(f"  {task}: " + ", ".join(f"{c} {r['success']}/{r['success'] + r['failure']}" for c, r in rows.items()))
    if args.json:
        print(json.dumps(summary))
    return 0


def _show(args: argparse.Namespace) -> int:
    import numpy as np

    from pilworld.collection.tasks import require_simulated, resolve_tasks
    from pilworld.io.run_folder import check_out_file
    from pilworld.io.video import write_png
    from simrig.robot import SimRobot

    check_count(args.scale, "--scale", SCALE)
    check_count(args.seed, "--seed", SEED)
    check_count(args.subtask, "--subtask", SUBTASK_INDEX)
    check_out_file(args.out, "--out", suffixes=(".png",))
    (task,) = resolve_tasks([args.task], what="--task")
    require_simulated([task], what="--task")
    with SimRobot(args.rig, task) as robot:
        start = robot.reset(seed=args.seed, subtask=args.subtask, history=0)
        row = np.concatenate([start.observation.images[v] for v in robot.spec.cameras], axis=1)
    if args.scale > 1:
        row = np.repeat(np.repeat(row, args.scale, axis=0), args.scale, axis=1)
    write_png(row, args.out)
    print(
        f"sim show: {args.task} seed {args.seed} subtask {args.subtask} → {args.out} ({', '.join(robot.spec.cameras)})"
    )
    return 0
