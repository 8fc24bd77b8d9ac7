"""``pilworld imagine`` (imagined-only runs from stored starts) and ``pilworld plan-trials`` (how many real trials).

See :mod:`pilworld.imagine.runner` and :mod:`pilworld.ppi` (docs/ppi.md).
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from pilworld.judges.learned.folder import JudgeFolder

REFERENCE = "reference"  # --judge: the paper tasks' hand-written judge (pilworld/reference/), on request only


def register(sub: Any) -> None:
    p: argparse.ArgumentParser = sub.add_parser(
        "imagine",
        help="run only the imagined branch from stored starts (resumable; worker processes or a Ray cluster)",
        description="For every stored start x checkpoint, the policy in closed loop against the world model, as in "
        "a paired run's imagined branch (the same start and seed give the same episode, bit for bit), then judged "
        "by a learned judge and the task-free hallucination detector. --starts takes a starts folder "
        "(pilworld paired record-starts), a paired run "
        "(its own starts) or any episode store. Rerunning the same command resumes.",
    )
    p.add_argument("--starts", type=Path, required=True, help="starts folder, paired run, or episode store")
    p.add_argument("--checkpoints", required=True, help="policy checkpoints, comma-separated (scripted names, ws://)")
    p.add_argument("--out", type=Path, required=True, help="run folder (created, or resumed)")
    p.add_argument("--rig", type=Path, default=None, help="rig config (default: the one the starts were recorded on)")
    p.add_argument(
        "--world-model",
        default="",
        help="world-model folder, v2 (composite), v1 (latent) or Wan2.1 (diffusers), known by its contents "
        "(default: the packaged v2)",
    )
    p.add_argument("--adapter", default="auto", help="LoRA adapter: auto, none, or a name (default auto)")
    p.add_argument("--steps", type=int, default=None, help="sampling steps (default: the model's)")
    p.add_argument("--rounds", type=int, default=None, help="closed-loop rounds (default: the starts' own, else 5)")
    p.add_argument("--count", type=int, default=None, help="use the first N starts of the source (default all)")
    p.add_argument(
        "--task",
        default="",
        help="the task file(s) of the starts' tasks (packaged names or .yaml files, comma-separated): what a "
        "scripted checkpoint acts on and whose hash the episodes record (default: the packaged task of each name)",
    )
    p.add_argument(
        "--instruction", default=None, help="the instruction given to the policy and recorded (default: the starts')"
    )
    p.add_argument("--start-frame", type=int, default=None, help="a plain dataset's start frame (default H_h)")
    p.add_argument("--video-mode", default="lossless", choices=["lossless", "h264", "av1"])
    p.add_argument("--workers", type=int, default=1, help="worker processes on this machine (default 1)")
    p.add_argument("--ray", default=None, metavar="ADDRESS", help="run on a Ray cluster (HOST:PORT, auto, or local)")
    p.add_argument("--no-judge", action="store_true", help="store the episodes without judging them")
    p.add_argument(
        "--judge",
        default=None,
        metavar="JUDGE",
        help="a learned judge folder (pilworld judge train): it judges success, the task-free detector "
        "hallucinations, and what it abstains on is queued for people (default: the shipped judge, trained on the "
        f"paper's three tasks, which abstains on any other task); {REFERENCE!r}: the paper tasks' hand-written judge",
    )
    p.add_argument("--judge-workers", type=int, default=None, help="processes judging the episodes (default: CPUs)")
    p.add_argument("--json", action="store_true", help="print the summary as one JSON object on the last line")
    p.set_defaults(handler=_imagine)

    t: argparse.ArgumentParser = sub.add_parser(
        "plan-trials",
        help="how many real trials a target interval needs, with and without imagined-only ones (from a pilot run)",
        description="Reads a pilot paired run's real and imagined outcomes per checkpoint (success rate p and the "
        "per-pair correlation rho of real and imagined verdicts) and says how many real trials give a 95 %% interval "
        "of the real success rate with the asked half-width: classically, and with N imagined-only subtasks by "
        "PPI++; and how many imagined ones are worth running.",
    )
    t.add_argument("run_dir", type=Path, metavar="RUN_DIR", help="a pilot paired run")
    t.add_argument(
        "--half-width", type=float, required=True, help="target interval half-width, e.g. 0.05 [0.0001, 0.5)"
    )
    t.add_argument("--alpha", type=float, default=0.05, help="1 - confidence level (default 0.05)")
    t.add_argument("--checkpoint", default=None, help="plan for one checkpoint (default: each, and all together)")
    t.add_argument("--json", action="store_true", help="print the plans as one JSON object on the last line")
    t.set_defaults(handler=_plan_trials)


def _imagine(args: argparse.Namespace) -> int:
    from pilworld.imagine.runner import ImagineConfig, imagine_run
    from pilworld.options.bounds import ROUNDS, SAMPLING_STEPS, STARTS, WORKERS, check_count
    from pilworld.types import ChunkSpec

    check_count(args.rounds, "--rounds", ROUNDS)
    check_count(args.steps, "--steps", SAMPLING_STEPS)
    check_count(args.count, "--count", STARTS)
    check_count(args.workers, "--workers", WORKERS)
    check_count(args.judge_workers, "--judge-workers", WORKERS)
    learned = None
    if args.judge is not None and args.no_judge:
        raise ValueError("--judge and --no-judge: choose one")
    if not args.no_judge and args.judge != REFERENCE:
        from pilworld.judges.learned.folder import load_judge
        from pilworld.judges.learned.shipped import SHIPPED_JUDGE

        # A missing or damaged judge folder is refused before anything runs.
        learned = load_judge(Path(args.judge) if args.judge is not None else SHIPPED_JUDGE)
    checkpoints = [c.strip() for c in args.checkpoints.split(",")]
    if not all(checkpoints):
        raise ValueError(f"--checkpoints: expected checkpoint names separated by commas, got {args.checkpoints!r}")
    from pilworld.collection.tasks import check_instruction, resolve_tasks

    if args.task.strip():
        resolve_tasks(args.task, what="--task")
    check_instruction(args.instruction, "--instruction")
    cfg = ImagineConfig(
        starts=str(args.starts),
        checkpoints=checkpoints,
        out=str(args.out),
        rig=str(args.rig) if args.rig else "",
        world_model=args.world_model,
        adapter=args.adapter,
        steps=args.steps,
        video_mode=args.video_mode,
        spec=ChunkSpec(rounds=args.rounds) if args.rounds is not None else None,
        start_frame=args.start_frame,
        count=args.count,
        task=args.task,
        instruction=args.instruction or "",
    )
    backend = None
    if args.ray:
        from pilworld.imagine.ray_backend import ray_backend

        backend = ray_backend(args.ray)
    summary = imagine_run(cfg, workers=args.workers, backend=backend, progress=not args.json)
    if not args.no_judge:
        summary["judged"] = judge_run(args.out, workers=args.judge_workers, progress=not args.json, learned=learned)
    if learned is not None and summary.get("judged", {}).get("abstained"):
        print(f"  {len(summary['judged']['abstained'])} episodes left to people: "
              f"pilworld annotate serve {args.out} --judges N --abstained")  # fmt: skip
    print(
        f"imagine: {summary['branches_planned']} branches ({summary['scenes']} starts × {len(cfg.checkpoints)} "
        f"checkpoints) in {summary['out']}; {summary['branches_run']} run in {summary['seconds']} s"
    )
    for ckpt, rate in (summary.get("judged") or {}).get("success_rate", {}).items():
        print(f"  {ckpt}: imagined success rate {100 * rate:.0f}%")
    if args.json:
        print(json.dumps(summary))
    return 0


def judge_run(
    root: Path, *, workers: int | None, progress: bool, learned: Path | JudgeFolder | None = None
) -> dict[str, Any]:
    """The automatic judges on every episode not judged yet; the imagined success rate per checkpoint.

    ``learned``: a learned judge folder (its path, or as loaded), which judges success (abstaining where
    unsure) with the task-free hallucination detector (:mod:`pilworld.judges.learned.apply`); without one,
    the paper tasks' hand-written judge (success and hallucinations)."""
    from pilworld.config.rig import RigConfig
    from pilworld.data.outcomes import read_outcomes
    from pilworld.data.reader import EpisodeStore
    from pilworld.imagine.runner import CONFIG_FILE
    from pilworld.judges.base import Judge, judge_dataset, unjudged_episodes
    from pilworld.judges.learned.apply import LEARNED_ID, apply_judge
    from pilworld.judges.learned.judge import LearnedSuccessJudge
    from pilworld.judges.vision import VisionJudge

    if not (root / "meta" / "info.json").is_file():
        return {"episodes": 0, "success_rate": {}}
    rig = RigConfig.load(json.loads((root / CONFIG_FILE).read_text())["rig"])
    abstained: list[int] | None = None
    if learned is None:
        judge: Judge = VisionJudge()
        success_id = judge.judge_id
        todo = unjudged_episodes(root, judge.judge_id)
        judge_dataset(root, [judge], rig, episodes=todo, progress=progress, workers=workers)
    else:
        applied = apply_judge(LearnedSuccessJudge(learned), root, rig, workers=workers, progress=progress)
        todo, abstained, success_id = list(range(applied.episodes)), applied.abstained, LEARNED_ID
    store = EpisodeStore(root)
    ckpt = {int(r["episode_index"]): str(r.get("checkpoint") or "") for r in store.episodes}
    per: dict[str, list[float]] = {}
    for o in read_outcomes(root):
        if o.judge_id == success_id:
            per.setdefault(ckpt[o.episode_index], []).append(float(o.success))
    out: dict[str, Any] = {"episodes": len(todo), "success_rate": {c: sum(v) / len(v) for c, v in sorted(per.items())}}
    if abstained is not None:
        out["abstained"] = abstained
    return out


MIN_HALF_WIDTH = 1e-4


def _plan_trials(args: argparse.Namespace) -> int:
    from pilworld.ppi.outcomes import read_run_outcomes
    from pilworld.ppi.planning import pilot_agreement, plan_trials

    if not MIN_HALF_WIDTH <= args.half_width < 0.5:
        raise ValueError(
            f"--half-width: expected a number in [{MIN_HALF_WIDTH:g}, 0.5) (a success rate's interval half-width; "
            f"below {MIN_HALF_WIDTH:g} no number of trials is practical), got {args.half_width:g}"
        )
    if not 1e-6 <= args.alpha < 1:
        raise ValueError(f"--alpha: expected a number in [1e-06, 1) (1 - confidence level), got {args.alpha:g}")
    if not (args.run_dir / "paired_config.json").is_file():
        raise FileNotFoundError(f"RUN_DIR: {args.run_dir}: not a paired run (paired_config.json missing)")
    outcomes = read_run_outcomes(args.run_dir, imagined=[])
    groups = {c: (o.y, o.f) for c, o in sorted(outcomes.by_checkpoint.items()) if o.y}
    if args.checkpoint is not None:
        if args.checkpoint not in groups:
            raise ValueError(
                f"--checkpoint: {args.checkpoint} has no judged pairs in {args.run_dir} (has {', '.join(groups)})"
            )
        groups = {args.checkpoint: groups[args.checkpoint]}
    elif len(groups) > 1:
        groups["all checkpoints"] = (
            [y for g in groups.values() for y in g[0]],
            [f for g in groups.values() for f in g[1]],
        )
    if not groups:
        raise ValueError(f"{args.run_dir}: no pair has both a real and an imagined verdict (judge the run first)")
    plans = {}
    for name, (y, f) in groups.items():
        p, rho = pilot_agreement(y, f)
        plans[name] = {"pilot_pairs": len(y), **plan_trials(p, rho, args.half_width, alpha=args.alpha).to_json()}
    grid = list(next(iter(plans.values()))["with_imagined"])
    head = f"{'checkpoint':<22} {'pairs':>5} {'p':>5} {'rho':>5} {'real only':>9} " + " ".join(
        f"{'N=' + str(n):>7}" for n in grid
    )
    print(
        f"real trials for a ±{args.half_width:g} interval ({100 * (1 - args.alpha):g} %), by imagined-only subtasks N"
    )
    print(head + f" {'N=inf':>7} {'worth N':>8}")
    for name, plan in plans.items():
        cells = " ".join(f"{plan['with_imagined'][n]:>7}" for n in grid)
        print(
            f"{name:<22} {plan['pilot_pairs']:>5} {plan['p']:>5.2f} {plan['rho']:>5.2f} {plan['classical']:>9} "
            f"{cells} {plan['limit']:>7} {plan['imagined_worth']:>8}"
        )
    if args.json:
        print(json.dumps(plans))
    return 0
