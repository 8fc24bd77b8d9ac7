"""``pilworld paired run``: each subtask on the robot and in the world model from the same start.

See :mod:`pilworld.paired.runner` for what is stored and how a rerun resumes.
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path
from typing import Any

from pilworld.cli.bench import DEFAULT_RIG


def register(sub: Any) -> None:
    p: argparse.ArgumentParser = sub.add_parser("paired", help="paired real/imagined closed-loop runs")
    cmds = p.add_subparsers(dest="paired_command", metavar="COMMAND")
    cmds.required = True
    r = cmds.add_parser(
        "run",
        help="run subtasks on the robot and in the world model from the same start (resumable)",
        description="Each subtask twice from the same start observation, history, instruction, checkpoint and seed: "
        "in the world model (origin imagined) and on the robot (origin real). Rerunning the same command resumes.",
    )
    r.add_argument("--rig", type=Path, default=DEFAULT_RIG, help="rig config (default: the simulated rig)")
    r.add_argument(
        "--task", required=True, help="task(s): sort_cubes, stack_bowls, stack_blocks, comma-separated, or all"
    )
    r.add_argument(
        "--checkpoints",
        default=None,
        help="policy checkpoints, comma-separated: scripted names or openpi servers ws://host:port "
        "(default: the rig's best checkpoint)",
    )
    r.add_argument("--subtasks", type=int, required=True, help="subtasks per task and checkpoint")
    r.add_argument("--out", type=Path, required=True, help="run folder (created, or resumed)")
    r.add_argument("--seed", type=int, default=0, help="layout seed of the first subtasks (default 0)")
    r.add_argument("--world-model", default="", help="world-model folder (default: the packaged checkpoint)")
    r.add_argument(
        "--adapter", default="auto", help="LoRA adapter: auto (the task's, if packaged), none, or a name (default auto)"
    )
    r.add_argument("--steps", type=int, default=None, help="sampling steps (default: the model's)")
    r.add_argument("--rounds", type=int, default=5, help="closed-loop rounds per subtask, R (default 5)")
    r.add_argument("--video-mode", default="lossless", choices=["lossless", "h264", "av1"])
    r.add_argument("--json", action="store_true", help="print the summary as one JSON object on the last line")
    r.add_argument(
        "--unattended",
        action="store_true",
        help="fake rig only: nobody at the rig; the simulator lays out each scene and its checker judges "
        "(refused on real hardware; a hardware run otherwise needs an operator at a terminal)",
    )
    r.set_defaults(handler=_run)
    r.epilog = (
        "Exit status: 0 done; 1 a policy server failed (unreachable, handshake failed, timeout, server error, "
        "connection closed, invalid actions/reply) or a hardware run has no operator at a terminal; 2 bad "
        "arguments. Stored branches stay and rerunning the same command resumes. Timeouts: "
        "PILWORLD_POLICY_CONNECT_TIMEOUT / PILWORLD_POLICY_REPLY_TIMEOUT (seconds, default 10 / 30)."
    )

    s = cmds.add_parser(
        "record-starts",
        help="record subtask starts (start observation + history) without running a policy (resumable)",
        description="On the simulated rig: seeded layouts. On a hardware rig: the operator lays out each scene and "
        "the rig records the start and its history while the arms hold still. pilworld imagine --starts DIR then "
        "runs imagined-only branches from them.",
    )
    s.add_argument("--rig", type=Path, default=DEFAULT_RIG, help="rig config (default: the simulated rig)")
    s.add_argument(
        "--task", required=True, help="task(s): sort_cubes, stack_bowls, stack_blocks, comma-separated, or all"
    )
    s.add_argument("--count", type=int, required=True, help="starts per task")
    s.add_argument("--out", type=Path, required=True, help="starts folder (created, or resumed)")
    s.add_argument("--seed", type=int, default=0, help="layout seed of the first starts (default 0)")
    s.add_argument("--rounds", type=int, default=5, help="closed-loop rounds the starts are meant for (default 5)")
    s.add_argument("--json", action="store_true", help="print the summary as one JSON object on the last line")
    s.add_argument(
        "--unattended",
        action="store_true",
        help="fake rig only: the simulator lays out each scene, nobody is asked (refused on real hardware)",
    )
    s.set_defaults(handler=_record_starts)


def _operator(args: argparse.Namespace) -> Any:
    """``--unattended``: nobody answers (the station refuses it on real hardware); else the terminal."""
    from pilworld.paired.operator import UnattendedOperator

    return UnattendedOperator() if args.unattended else None


def _record_starts(args: argparse.Namespace) -> int:
    from pilworld.paired.record_starts import record_starts
    from pilworld.types import ChunkSpec

    if args.count < 1:
        raise ValueError(f"--count: expected at least 1, got {args.count}")
    summary = record_starts(
        str(args.rig),
        args.task,
        args.count,
        args.out,
        seed=args.seed,
        spec=ChunkSpec(rounds=args.rounds),
        progress=not args.json,
        operator=_operator(args),
    )
    print(f"record-starts: {summary['starts_recorded']} of {summary['starts_planned']} starts recorded in {args.out}")
    if args.json:
        print(json.dumps(summary))
    return 0


def _run(args: argparse.Namespace) -> int:
    from pilworld.paired import PairedConfig, paired_run
    from pilworld.policies.registry import default_checkpoint
    from pilworld.types import ChunkSpec

    ckpts = [c.strip() for c in args.checkpoints.split(",")] if args.checkpoints else [default_checkpoint()]
    if args.rounds < 1:
        raise ValueError(f"--rounds: expected at least 1, got {args.rounds}")
    cfg = PairedConfig(
        rig=str(args.rig),
        task=args.task,
        checkpoints=ckpts,
        subtasks=args.subtasks,
        out=str(args.out),
        seed=args.seed,
        world_model=args.world_model,
        adapter=args.adapter,
        steps=args.steps,
        video_mode=args.video_mode,
        spec=ChunkSpec(rounds=args.rounds),
    )
    summary = paired_run(cfg, progress=not args.json, operator=_operator(args))
    ds = summary["dataset"]
    origins = ", ".join(f"{o} {d['episodes']}" for o, d in ds["by_origin"].items())
    print(
        f"paired run: {summary['pairs_planned']} subtasks in {summary['out']} ({origins} episodes); "
        f"{summary['branches_run']} branches run in {summary['seconds']} s"
    )
    for origin, t in summary["seconds_per_subtask"].items():
        print(f"  {origin}: {t['median']} s per subtask (median of {t['n']})")
    if args.json:
        print(json.dumps(summary))
    return 0
