"""``pilworld bench wm-ladder``: the diagnostic ladder — where does the imagined branch lose?

The imagined branch differs from the real one in several ways at once: the policy sees generated frames,
its state is the last commanded action instead of the measured joints, the judges look at frames with
model artefacts, and the model's errors compound from round to round. Each rung isolates one of them on
the simulated rig (layouts from seed 8,000,000 on, reserved for this bench; training used 0–19), on the
same plan of pairs (tasks × scripted checkpoints × subtasks, :func:`pilworld.paired.runner.plan_subtasks`):

0. ``state_contract`` — the real branch against branches with *perfect* images (the simulator) but the
   imagined branch's state contract: every observation's state replaced by the executed stride-aligned
   commands (``commanded``), or only the arm joints commanded and the grippers measured
   (``arms_commanded``). SR by the privileged checker.
1. ``representation`` — the real branch re-run with every observation the policy sees passed through the
   world model's frame autoencoder (encode → decode; the robot itself is unaffected): SR by the checker,
   and the image-only judge (:class:`~pilworld.judges.vision.VisionJudge`) on plain and on autoencoded
   episodes — its agreement with the checker and the hallucination detector's false-positive rate (any
   flagged frame on a real episode is a false positive). ``null`` for a model without an autoencoder.
2. ``judge_fairness`` — the plain real episodes judged again after a degradation that a world model's
   frames carry without being wrong: the autoencoder, a mild Gaussian blur (σ = 1 px at 128²), and
   "artefacts" (JPEG at quality 80, per-frame noise σ = 2 levels, per-frame colour shift σ = 2 levels).
   Success agreement, false-positive rate, and the recall of one injected fault per episode
   (:mod:`pilworld.judges.faults`, found within k ± 1 as in ``pilworld bench hallucination``); beside the
   hand-written judge, a learned one (``--judge``, default the shipped judge; ``none``: none) with its drop
   from the plain episodes on those it judged both ways.
3. ``teacher_forced`` — per round r = 1..R, pooled PSNR of the model's K frames against the real K
   frames, when every round starts from the real frames (the real observation at the round start, its
   real history, the real executed chunk: one-chunk quality) and in the free closed loop (the same real
   chunks, the model's own frames fed back: compounding), beside the frozen baselines (the round's real
   start frame held, and the subtask's start frame held). Round 1 is the same in both by construction. Both
   judges also judge each real episode's teacher-forced re-render (every frame after the start predicted
   from the real frames before it): docs/judges.md, "Fairness".

Everything resumes from ``--out`` (default ``bench_runs/wm_ladder``): every pair's record of every rung
is appended to ``<rung>.jsonl`` (keyed by the settings that decide it), and every real branch is kept as
``real/<key>/<pair>.npz`` and shared by the rungs (it does not depend on the world model).

docs/world_model.md, "Diagnostic ladder", has the figures. The package follows the ladder: its settings
(:mod:`.settings`), the model and its autoencoder (:mod:`.model`), the wrapped real branches (:mod:`.envs`),
the degradations (:mod:`.degrade`), the lab and its caches (:mod:`.lab`, :mod:`.real_store`), the statistics
(:mod:`.stats`), one module per rung, and the ladder itself (:mod:`.ladder`); this module adds
``pilworld bench wm-ladder``'s options and run.
"""

from __future__ import annotations

import argparse
from pathlib import Path

from pilworld.bench.flags import add_json, add_rig
from pilworld.bench.output import emit
from pilworld.bench.wm_ladder.degrade import degrade_episode
from pilworld.bench.wm_ladder.envs import AutoencodedEnv, StateContractEnv
from pilworld.bench.wm_ladder.lab import Lab
from pilworld.bench.wm_ladder.ladder import run_wm_ladder, summary_lines
from pilworld.bench.wm_ladder.model import FrameAutoencoder, SeedShifted, autoencoder_for, load_ladder_model
from pilworld.bench.wm_ladder.settings import (
    DEFAULT_OUT,
    DEGRADATIONS,
    LADDER_SEED0,
    RUNGS,
    STATE_MODES,
    TASKS,
    LadderConfig,
)
from pilworld.bench.wm_ladder.teacher_forced import (
    teacher_forced_episode,
    teacher_forced_errors,
    teacher_forced_predictions,
)
from pilworld.options.bounds import at_least_one
from pilworld.options.parse import parse_list
from pilworld.types import ChunkSpec

__all__ = [
    "DEFAULT_OUT",
    "DEGRADATIONS",
    "LADDER_SEED0",
    "RUNGS",
    "STATE_MODES",
    "TASKS",
    "AutoencodedEnv",
    "FrameAutoencoder",
    "Lab",
    "LadderConfig",
    "SeedShifted",
    "StateContractEnv",
    "autoencoder_for",
    "degrade_episode",
    "load_ladder_model",
    "run_wm_ladder",
    "summary_lines",
    "teacher_forced_episode",
    "teacher_forced_errors",
    "teacher_forced_predictions",
]


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--quick", action="store_true", help="3 tasks × 3 checkpoints × 1 subtask (≤ 5 min on 2 cores)")
    parser.add_argument(
        "--subtasks", type=int, default=None, help="subtasks per task × checkpoint (default 1 quick / 2)"
    )
    parser.add_argument("--model", type=Path, default=None, help="world-model folder (default: v1, sim_small)")
    add_rig(parser)
    parser.add_argument("--rungs", default="", help="comma-separated rungs (default: all four)")
    parser.add_argument("--tasks", default="all", help="comma-separated tasks (default all three)")
    parser.add_argument(
        "--checkpoints", default="", help="comma-separated scripted checkpoints (default: 3 quick / all 5)"
    )
    parser.add_argument("--rounds", type=int, default=None, help="closed-loop rounds per subtask (default 5)")
    parser.add_argument(
        "--judge",
        default="",
        help="learned judge folder that rungs 2 and 3 run beside the hand-written judge (default: the shipped one; "
        "'none': only the hand-written)",
    )
    parser.add_argument("--out", type=Path, default=None, help="cache folder, resumed (default bench_runs/wm_ladder)")
    parser.add_argument("--threads", type=int, default=None, help="torch CPU threads (default: torch's own)")
    parser.add_argument("--no-progress", action="store_true", help="no progress bars on stderr")
    add_json(parser)


def run(args: argparse.Namespace) -> int:
    """The rungs of the options (or all four), resumed from ``--out``, and one summary line per rung."""
    at_least_one(args, "subtasks", "threads")
    if args.threads is not None:
        import torch

        torch.set_num_threads(args.threads)
    at_least_one(args, "rounds")

    cfg = LadderConfig(
        model=str(args.model) if args.model is not None else "",
        rig=str(args.rig),
        quick=args.quick,
        subtasks=args.subtasks,
        tasks=TASKS if args.tasks.strip() == "all" else tuple(parse_list(args.tasks)),
        checkpoints=tuple(parse_list(args.checkpoints)) or None,
        rungs=tuple(parse_list(args.rungs)) or RUNGS,
        spec=ChunkSpec() if args.rounds is None else ChunkSpec(rounds=args.rounds),
        out=str(args.out or DEFAULT_OUT),
        judge=args.judge,
    )
    r = run_wm_ladder(cfg, progress=not args.no_progress)
    return emit(args, r, summary_lines(r))
