"""``pilworld demo``: paired runs, judges, metrics and the report on the simulated rig (see :mod:`pilworld.demo`)."""

from __future__ import annotations

import argparse
import json
from pathlib import Path
from typing import Any

from simrig.files import SIM_RIG


def register(sub: Any) -> None:
    p: argparse.ArgumentParser = sub.add_parser(
        "demo",
        help="the main job: paired real/imagined evaluation on the simulated rig, judged, with metrics and a report",
        description="Runs every task x checkpoint x subtask on the simulated robot and in the shipped world model from "
        "the same start, judges both branches, and writes metrics.json, the dataset and report.html into --out. "
        "Rerunning the same command resumes.",
    )
    p.add_argument(
        "--out", type=Path, default=Path("runs/demo/paired"), help="output folder (default runs/demo/paired)"
    )
    p.add_argument("--full", action="store_true", help="the larger protocol: all 5 checkpoints, 20 subtasks each")
    p.add_argument("--subtasks", type=int, default=None, help="subtasks per task and checkpoint (default 6; --full 20)")
    p.add_argument("--rounds", type=int, default=None, help="closed-loop rounds per subtask (default 5)")
    p.add_argument("--seed", type=int, default=None, help="first layout seed (default 5000000, unseen in training)")
    p.add_argument("--rig", type=Path, default=SIM_RIG, help="rig config (default: the simulated rig)")
    p.add_argument("--workers", type=int, default=None, help="processes judging the episodes (default: CPUs)")
    p.add_argument(
        "--appearance",
        choices=("flat", "varied"),
        default="flat",
        help="the simulated rig's look: flat (default, the shipped world model's training look) or varied "
        "(textures, random light, camera noise; docs/sim_rig.md)",
    )
    p.add_argument(
        "--judge",
        type=Path,
        default=None,
        help="learned judge folder SR and HFR come from (default: the shipped one, trained on the flat look; "
        "under --appearance varied none ships, and the hand-written reference is selected unless you name one)",
    )
    p.add_argument("--json", action="store_true", help="print the summary as one JSON object on the last line")
    p.set_defaults(handler=_demo)


def _demo(args: argparse.Namespace) -> int:
    from pilworld.demo import DEMO_SEED0, run_demo, summary_table

    result = run_demo(
        args.out,
        rig=args.rig,
        full=args.full,
        subtasks=args.subtasks,
        rounds=args.rounds,
        seed=DEMO_SEED0 if args.seed is None else args.seed,
        progress=not args.json,
        workers=args.workers,
        appearance=args.appearance,
        judge=args.judge,
    )
    print(summary_table(result["metrics"]))
    st = result["stages"]
    print(
        f"demo: {result['pairs']} paired subtasks ({', '.join(result['size']['checkpoints'])}) in {st['total_s']} s "
        f"(paired runs {st['paired_runs_s']} s, judging {st['judging_s']} s + {st['learned_judge_s']} s learned, "
        f"report {st['report_s']} s)"
    )
    print(f"  metrics: {result['metrics_json']}\n  report:  {result['report_html']}\n  dataset: {result['out']}")
    if args.json:
        print(json.dumps(result))
    return 0
