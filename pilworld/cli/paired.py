"""``pilworld paired run``: each subtask on the robot and in the world model from the same start.

See :mod:`pilworld.paired.runner` for what is stored and how a rerun resumes.
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path
from typing import TYPE_CHECKING, Any

from pilworld.collection.tasks import APPEARANCES
from pilworld.options.bounds import ROUNDS, SAMPLING_STEPS, SEED, STARTS, SUBTASKS, bounded, check_count
from simrig.files import SIM_RIG

if TYPE_CHECKING:
    from pilworld.judges.learned.judge import LearnedSuccessJudge


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
    r.add_argument("--rig", type=Path, default=SIM_RIG, help="rig config (default: the simulated rig)")
    r.add_argument("--task", required=True, help=TASK_HELP)
    task_options(r)
    r.add_argument(
        "--checkpoints",
        default=None,
        help="policy checkpoints, comma-separated: scripted names or openpi servers ws://host:port "
        "(default: the rig's best checkpoint)",
    )
    r.add_argument("--subtasks", type=int, required=True, help=bounded("subtasks per task and checkpoint", SUBTASKS))
    r.add_argument("--out", type=Path, required=True, help="run folder (created, or resumed)")
    r.add_argument("--seed", type=int, default=0, help=bounded("layout seed of the first subtasks (default 0)", SEED))
    r.add_argument(
        "--world-model",
        default="",
        help="world-model folder, v2 (composite), v1 (latent) or Wan2.1 (diffusers), known by its contents "
        "(default: the packaged v2)",
    )
    r.add_argument(
        "--adapter", default="auto", help="LoRA adapter: auto (the task's, if packaged), none, or a name (default auto)"
    )
    r.add_argument(
        "--steps", type=int, default=None, help=bounded("sampling steps (default: the model's)", SAMPLING_STEPS)
    )
    r.add_argument(
        "--rounds", type=int, default=5, help=bounded("closed-loop rounds per subtask, R (default 5)", ROUNDS)
    )
    r.add_argument("--video-mode", default="lossless", choices=["lossless", "h264", "av1"])
    r.add_argument(
        "--judge",
        type=Path,
        default=None,
        help="a learned judge folder (pilworld judge train): after the run it judges both branches of every pair "
        "(= pilworld judge apply JUDGE OUT), SR and HFR come from it, and metrics.json and report.html are written",
    )
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
    s.add_argument("--rig", type=Path, default=SIM_RIG, help="rig config (default: the simulated rig)")
    s.add_argument("--task", required=True, help=TASK_HELP)
    task_options(s)
    s.add_argument("--count", type=int, required=True, help=bounded("starts per task", STARTS))
    s.add_argument("--out", type=Path, required=True, help="starts folder (created, or resumed)")
    s.add_argument("--seed", type=int, default=0, help=bounded("layout seed of the first starts (default 0)", SEED))
    s.add_argument(
        "--rounds",
        type=int,
        default=5,
        help=bounded("closed-loop rounds the starts are meant for (default 5)", ROUNDS),
    )
    s.add_argument("--json", action="store_true", help="print the summary as one JSON object on the last line")
    s.add_argument(
        "--unattended",
        action="store_true",
        help="fake rig only: the simulator lays out each scene, nobody is asked (refused on real hardware)",
    )
    s.set_defaults(handler=_record_starts)


TASK_HELP = (
    "task(s): packaged names (sort_cubes, stack_bowls, stack_blocks) or task files (.yaml), comma-separated, "
    "or all (the paper's three)"
)


def task_options(p: argparse.ArgumentParser) -> None:
    """``--instruction`` and ``--appearance``, beside ``--task``."""
    p.add_argument(
        "--instruction",
        default=None,
        help="the instruction given to the policy and recorded (default: each task file's own)",
    )
    p.add_argument(
        "--appearance",
        default="flat",
        choices=APPEARANCES,
        help="the simulated scene's look (default flat; a hardware rig's scene is what stands on the table)",
    )


def check_tasks(args: argparse.Namespace) -> list[Any]:
    """``--task`` and ``--instruction`` checked before anything runs (one line naming the flag otherwise)."""
    from pilworld.collection.tasks import check_instruction, resolve_tasks
    from pilworld.config.rig import RigConfig
    from pilworld.paired.runner import check_station_tasks

    tasks = resolve_tasks(args.task, what="--task")
    check_instruction(args.instruction, "--instruction")
    rig = RigConfig.load(args.rig)
    check_station_tasks(rig, tasks, _operator(args), what="--task")
    if rig.hardware is not None and args.appearance != "flat":
        raise ValueError(
            f"--appearance: rig {rig.name!r} is a hardware rig; its scene is what stands on the table "
            f"({args.appearance!r} is for the simulated rig)"
        )
    return tasks


def _operator(args: argparse.Namespace) -> Any:
    """``--unattended``: nobody answers (the station refuses it on real hardware); else the terminal."""
    from pilworld.paired.operator import UnattendedOperator

    return UnattendedOperator() if args.unattended else None


def _record_starts(args: argparse.Namespace) -> int:
    from pilworld.paired.record_starts import record_starts
    from pilworld.types import ChunkSpec

    check_count(args.count, "--count", STARTS)
    check_count(args.seed, "--seed", SEED)
    check_count(args.rounds, "--rounds", ROUNDS)
    check_tasks(args)
    summary = record_starts(
        str(args.rig),
        args.task,
        args.count,
        args.out,
        seed=args.seed,
        spec=ChunkSpec(rounds=args.rounds),
        progress=not args.json,
        operator=_operator(args),
        instruction=args.instruction or "",
        appearance=args.appearance,
    )
    print(f"record-starts: {summary['starts_recorded']} of {summary['starts_planned']} starts recorded in {args.out}")
    if args.json:
        print(json.dumps(summary))
    return 0


def _run(args: argparse.Namespace) -> int:
    from pilworld.paired import PairedConfig, paired_run
    from pilworld.policies.registry import default_checkpoint
    from pilworld.types import ChunkSpec

    given = args.checkpoints is not None
    ckpts = [c.strip() for c in args.checkpoints.split(",")] if given else [default_checkpoint()]
    check_count(args.subtasks, "--subtasks", SUBTASKS)
    check_count(args.seed, "--seed", SEED)
    check_count(args.rounds, "--rounds", ROUNDS)
    check_count(args.steps, "--steps", SAMPLING_STEPS)
    if not ckpts or not all(ckpts):
        raise ValueError(f"--checkpoints: expected checkpoint names separated by commas, got {args.checkpoints!r}")
    check_tasks(args)
    learned = None
    if args.judge is not None:
        from pilworld.judges.learned.judge import LearnedSuccessJudge

        learned = LearnedSuccessJudge(args.judge)  # a missing or damaged folder: refused before the run
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
        instruction=args.instruction or "",
        appearance=args.appearance,
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
    if learned is not None:
        summary["judge"] = _judge_run(learned, args.out, args.rig, progress=not args.json)
    if args.json:
        print(json.dumps(summary))
    return 0


def _judge_run(learned: LearnedSuccessJudge, out: Path, rig_path: Path, *, progress: bool) -> dict[str, Any]:
    """``--judge``: the learned judge on both branches of every pair, selected, then metrics and the report."""
    from pilworld.cli.judge import rewrite_results
    from pilworld.config.rig import RigConfig
    from pilworld.judges.learned.apply import apply_judge

    rig = RigConfig.load(rig_path)
    applied = apply_judge(learned, out, rig, progress=progress, select_as="pilworld paired run --judge")
    print(f"judge {learned.folder.name!r}: {applied.judged} of {applied.episodes} episodes judged, "
          f"{len(applied.abstained)} left to people (pilworld annotate serve {out} --abstained)")  # fmt: skip
    return {"judged": applied.judged, "abstained": applied.abstained, **rewrite_results(out, rig)}
