"""``pilworld task check|show|try``: a task file (docs/tasks.md) checked, looked at, and tried on the simulated rig.

* ``check FILE…`` — every problem of each file, one line each naming the file and the field (exit 1 when
  there are any), else one line: the task's name, objects, subtasks and the start of its file hash.
* ``show FILE --out PNG`` — the start of every subtask (earlier subtasks done) on the simulated rig, each
  camera view side by side, one row per subtask.
* ``try FILE`` — the success rate of each scripted checkpoint on the real branch alone (the simulator's
  checker judges), and whether the checkpoints spread from worst ≤ 30 % to best ≥ 90 %, as the paper's
  tasks do (a task every checkpoint solves, or none does, cannot tell checkpoints apart).
"""

from __future__ import annotations

import argparse
import json
import os
import time
from pathlib import Path
from typing import Any

from pilworld.collection.tasks import APPEARANCES
from pilworld.options.parse import parse_names
from simrig.files import SIM_RIG

SPREAD_WORST = 0.3  # the worst checkpoint succeeds at most this often …
SPREAD_BEST = 0.9  # … and the best at least this often


def register(sub: Any) -> None:
    p: argparse.ArgumentParser = sub.add_parser(
        "task",
        help="task files: check one, show its subtask starts, try the scripted checkpoints on it",
        description="A task is a YAML file (docs/tasks.md): a packaged name (configs/tasks/) or any path.",
    )
    cmds = p.add_subparsers(dest="task_command", metavar="COMMAND")
    cmds.required = True

    c = cmds.add_parser(
        "check",
        help="validate task files: one line per problem (exit 1), or a one-line summary",
        epilog="Exit status: 0 every file is valid; 1 a file has problems (one line each); 2 bad arguments.",
    )
    c.add_argument("files", nargs="+", metavar="FILE", help="task file(s) (.yaml) or packaged task names")
    c.add_argument("--json", action="store_true", help="print the result as one JSON object on the last line")
    c.set_defaults(handler=_check)

    s = cmds.add_parser(
        "show",
        help="write the start of each subtask, every camera view side by side, one row per subtask (PNG)",
    )
    s.add_argument("file", metavar="FILE", help="task file (.yaml) or packaged task name")
    s.add_argument("--out", type=Path, required=True, help="PNG file to write")
    s.add_argument("--seed", type=int, default=0, help="layout seed (default 0)")
    s.add_argument("--appearance", default="flat", choices=APPEARANCES, help="scene appearance (default flat)")
    s.add_argument("--rig", type=Path, default=SIM_RIG, help="rig config (default: the simulated rig)")
    s.add_argument("--json", action="store_true", help="print the result as one JSON object on the last line")
    s.set_defaults(handler=_show)

    t = cmds.add_parser(
        "try",
        help="success rate of each scripted checkpoint on the task (simulated rig, real branch only)",
        description="Start i is subtask i mod n of layout seed S + i (as a paired run starts them); every "
        f"checkpoint sees the same starts. The spread holds when the worst checkpoint succeeds at most "
        f"{SPREAD_WORST:.0%} of the time and the best at least {SPREAD_BEST:.0%}.",
    )
    t.add_argument("file", metavar="FILE", help="task file (.yaml) or packaged task name")
    t.add_argument("--checkpoints", default="all", help="scripted checkpoints, comma-separated, or all (default)")
    t.add_argument("--subtasks", type=int, default=12, help="subtask starts per checkpoint (default 12) [1..1,000]")
    t.add_argument("--seed", type=int, default=0, help="layout seed of the first start (default 0)")
    t.add_argument("--appearance", default="flat", choices=APPEARANCES, help="scene appearance (default flat)")
    t.add_argument("--workers", type=int, default=None, help="processes (default: CPUs) [1..256]")
    t.add_argument("--rig", type=Path, default=SIM_RIG, help="rig config (default: the simulated rig)")
    t.add_argument("--json", action="store_true", help="print the result as one JSON object on the last line")
    t.set_defaults(handler=_try)


def _check(args: argparse.Namespace) -> int:
    from simrig.tasks import check_task_file, load_task

    results = []
    for name in args.files:
        problems = check_task_file(name)
        if problems:
            for line in problems:
                print(line)
            results.append({"file": name, "ok": False, "problems": problems})
            continue
        task = load_task(name)
        objects = len(task.object_names)
        kind = _count(objects, "object") if task.simulated else "no objects (hardware only: an operator lays it out)"
        print(
            f"{task.path}: OK: task {task.name!r}, {kind}, {_count(task.num_subtasks, 'subtask')}, "
            f"sha256 {task.digest[:12]}"
        )
        results.append(
            {
                "file": str(task.path),
                "ok": True,
                "problems": [],
                "name": task.name,
                "objects": objects,
                "subtasks": task.num_subtasks,
                "simulated": task.simulated,
                "task_sha256": task.digest,
            }
        )
    ok = all(r["ok"] for r in results)
    if args.json:
        print(json.dumps({"ok": ok, "files": results}))
    return 0 if ok else 1


def _count(n: int, noun: str) -> str:
    return f"{n} {noun}{'' if n == 1 else 's'}"


def check_png_out(out: Path) -> None:
    """``--out`` can take a PNG: a ``.png`` name, not a folder, in a folder that exists or can be made (checked
    before anything is simulated)."""
    if out.suffix.lower() != ".png":
        raise ValueError(f"--out: {out}: expected a .png file name")
    if out.is_dir():
        raise ValueError(f"--out: {out} is a folder; give a .png file name")
    parent = out.resolve().parent
    while not parent.exists():
        parent = parent.parent
    if not parent.is_dir():
        raise ValueError(f"--out: {parent} is not a folder")
    if not os.access(parent, os.W_OK | os.X_OK) or (out.exists() and not os.access(out, os.W_OK)):
        raise ValueError(f"--out: {out} is not writable")


def _simulated_task(name: str) -> Any:
    """The task FILE names, loaded and buildable on the simulated rig; one line naming the file otherwise."""
    from pilworld.collection.tasks import not_simulated
    from simrig.tasks import load_task

    task = load_task(name)  # TaskFileError (a ValueError): its first problem, naming file and field
    if not task.simulated:
        raise ValueError(not_simulated(task))
    return task


def _show(args: argparse.Namespace) -> int:
    import numpy as np

    from pilworld.io.run_folder import check_out_file
    from pilworld.io.video import write_png
    from pilworld.options.bounds import SEED, check_count
    from simrig.robot import SimRobot

    check_png_out(args.out)
    check_out_file(args.out, "--out", suffixes=(".png",))  # a name OpenCV can take, a folder it can write
    check_count(args.seed, "--seed", SEED)
    task = _simulated_task(args.file)
    rows = []
    with SimRobot(args.rig, task, appearance=args.appearance) as robot:
        views = list(robot.spec.cameras)
        for k in range(task.num_subtasks):
            robot.reset(seed=args.seed, subtask=k, history=0)
            obs = robot.observe()
            rows.append(np.concatenate([obs.images[v] for v in views], axis=1))
    image = np.concatenate(rows, axis=0)
    write_png(image, args.out)
    height, width = image.shape[:2]
    print(
        f"task show: {task.name} seed {args.seed}: {task.num_subtasks} subtask starts (rows) × "
        f"{', '.join(views)} (columns) → {args.out} ({width}x{height})"
    )
    if args.json:
        summary = {
            "task": task.name,
            "file": str(task.path),
            "task_sha256": task.digest,
            "seed": args.seed,
            "appearance": args.appearance,
            "out": str(args.out),
            "views": views,
            "subtasks": task.num_subtasks,
            "width": width,
            "height": height,
        }
        print(json.dumps(summary))
    return 0


def _try(args: argparse.Namespace) -> int:
    from pilworld.collection.evaluate import success_rates
    from pilworld.options.bounds import SEED, TRY_SUBTASKS, WORKERS, check_count
    from pilworld.policies.scripted import CHECKPOINTS
    from pilworld.types import ChunkSpec

    check_count(args.subtasks, "--subtasks", TRY_SUBTASKS)
    check_count(args.workers, "--workers", WORKERS)
    check_count(args.seed, "--seed", SEED)
    ckpts = parse_names(args.checkpoints, [c.name for c in CHECKPOINTS], "--checkpoints")
    task = _simulated_task(args.file)
    t0 = time.monotonic()
    rates = success_rates(
        str(args.rig),
        [task],
        ckpts,
        args.subtasks,
        seed0=args.seed,
        workers=args.workers,
        spec=ChunkSpec(),
        progress=not args.json,
        appearance=args.appearance,
    )[task.name]
    wall = time.monotonic() - t0
    worst = min(rates, key=lambda c: rates[c])
    best = max(rates, key=lambda c: rates[c])
    holds = rates[worst] <= SPREAD_WORST and rates[best] >= SPREAD_BEST
    print(
        f"task try: {task.name} ({task.path}, sha256 {task.digest[:12]}), {args.subtasks} subtask starts per "
        f"checkpoint from layout seed {args.seed}, {args.appearance} appearance, {wall:.1f} s"
    )
    print(f"  {'checkpoint':<24} {'successes':>9} {'rate':>6}")
    for c, r in rates.items():
        print(f"  {c:<24} {round(r * args.subtasks):>5}/{args.subtasks:<3} {100 * r:>5.0f}%")
    print(
        f"spread {'holds' if holds else 'does not hold'}: worst {100 * rates[worst]:.0f}% ({worst}, needs ≤ "
        f"{100 * SPREAD_WORST:.0f}%), best {100 * rates[best]:.0f}% ({best}, needs ≥ {100 * SPREAD_BEST:.0f}%)"
    )
    if args.json:
        summary = {
            "task": task.name,
            "file": str(task.path),
            "task_sha256": task.digest,
            "subtasks": args.subtasks,
            "seed": args.seed,
            "appearance": args.appearance,
            "rates": rates,
            "spread": {
                "worst": rates[worst],
                "worst_checkpoint": worst,
                "best": rates[best],
                "best_checkpoint": best,
                "holds": holds,
                "needs": {"worst_at_most": SPREAD_WORST, "best_at_least": SPREAD_BEST},
            },
            "wall_s": round(wall, 1),
        }
        print(json.dumps(summary))
    return 0
