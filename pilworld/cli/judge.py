"""``pilworld judge train|evaluate|apply|select|show``: a success judge learned from labelled episodes (docs/judges.md).

* ``train --data DIR[,DIR…] --out JUDGE [--labels sim_checker|operator|human]`` — a judge from the labelled
  episodes of one or more datasets (any task: the instruction and subtask index are inputs, nothing else
  about the task is read); it reports its out-of-fold agreement and the confidence below which it abstains.
* ``evaluate JUDGE --data DIR[,DIR…] [--degrade blur|coarse|noise]`` — agreement with the labels of
  episodes it did not see, abstentions apart; ``--degrade`` first passes the frames through what
  imagined frames suffer.
* ``apply JUDGE RUN_DIR`` — verdicts on every episode of a run (both branches) as judge ``learned``, the
  episodes it abstains on listed for people (``pilworld annotate serve RUN_DIR --abstained``), then the
  run's metrics.json and report.html again.
* ``select RUN_DIR JUDGES|all`` — which judges' verdicts the run's SR and HFR come from (``apply`` selects
  ``learned`` unless ``--no-select``), recorded in the run folder.
* ``show JUDGE`` — what a judge folder holds: its inputs, data, threshold and validation.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path
from typing import TYPE_CHECKING, Any

from pilworld.options.bounds import WORKERS, Bound, bounded, check_count
from pilworld.options.parse import parse_list

if TYPE_CHECKING:
    from pilworld.config.rig import RigConfig

FOLDS = Bound(2, 20, "networks, each validated on the episodes the others train on")
STEPS = Bound(1, 100_000, "optimiser steps per network")
SEED = Bound(0, 2**32 - 1, "a training seed")
RIG_HELP = "the rig the episodes were recorded on (default: the simulated rig)"


def register(sub: Any) -> None:
    p: argparse.ArgumentParser = sub.add_parser(
        "judge",
        help="learned success judges: train one from labelled episodes, evaluate it, show it",
        description="A success judge learned from labelled episodes of any task (docs/judges.md).",
    )
    cmds = p.add_subparsers(dest="judge_command", metavar="COMMAND")
    cmds.required = True

    t = cmds.add_parser("train", help="train a judge on the labelled episodes of one or more datasets")
    t.add_argument("--data", required=True, help="dataset or run folder(s), comma-separated")
    t.add_argument("--out", type=Path, required=True, help="judge folder to write (new or empty)")
    t.add_argument(
        "--labels",
        default="sim_checker",
        choices=("sim_checker", "operator", "human"),
        help="whose verdicts to learn: the simulator's checker (default), the operator's, human judges' (majority)",
    )
    t.add_argument("--folds", type=int, default=5, help=bounded("networks in the ensemble (default 5)", FOLDS))
    t.add_argument("--steps", type=int, default=None, help=bounded("optimiser steps per network (default 300)", STEPS))
    t.add_argument("--seed", type=int, default=0, help=bounded("training seed (default 0)", SEED))
    t.add_argument(
        "--release-crop",
        type=int,
        default=0,
        help="also read a crop of this many head pixels where a gripper last let go (0: off) [8..256]",
    )
    t.add_argument(
        "--imagined",
        type=float,
        default=0.5,
        help="share of training samples whose end frames are softened and tinted as a world model renders them "
        "(default 0.5; 0: off) [0..1]",
    )
    t.add_argument(
        "--abstain-budget",
        type=float,
        default=0.04,
        help="abstain on at most this share of the validation episodes to reach 99 %% there (default 0.04) [0..0.9]",
    )
    t.add_argument("--rig", type=Path, default=None, help=RIG_HELP)
    t.add_argument("--name", default="", help="the judge's name (default: the folder's)")
    t.add_argument("--json", action="store_true", help="print the result as one JSON object on the last line")
    t.set_defaults(handler=_train)

    e = cmds.add_parser("evaluate", help="agreement of a judge with the labels of episodes it did not see")
    e.add_argument("judge", type=Path, metavar="JUDGE", help="judge folder (pilworld judge train)")
    e.add_argument("--data", required=True, help="dataset or run folder(s), comma-separated")
    e.add_argument("--labels", default="sim_checker", choices=("sim_checker", "operator", "human"))
    e.add_argument("--degrade", default="", choices=("", "blur", "coarse", "noise"), help="degrade frames first")
    e.add_argument("--rig", type=Path, default=None, help=RIG_HELP)
    e.add_argument("--json", action="store_true", help="print the result as one JSON object on the last line")
    e.set_defaults(handler=_evaluate)

    a = cmds.add_parser(
        "apply",
        help="judge every episode of a run; abstentions are queued for people",
        description="Verdicts of a learned judge on both branches of every pair of a run, recorded as judge "
        "'learned'; the episodes it abstains on are listed in RUN_DIR/judges/learned.json and queued for people by "
        "'pilworld annotate serve RUN_DIR --abstained'. Resumable; applying another judge folder replaces the "
        "previous one's verdicts. Then metrics.json and report.html are written again.",
    )
    a.add_argument("judge", type=Path, metavar="JUDGE", help="judge folder (pilworld judge train)")
    a.add_argument("run_dir", type=Path, metavar="RUN_DIR", help="a paired run (or any episode store)")
    a.add_argument("--rig", type=Path, default=None, help=RIG_HELP)
    a.add_argument("--workers", type=int, default=1, help=bounded("judging processes (default 1)", WORKERS))
    a.add_argument("--no-report", action="store_true", help="do not write metrics.json and report.html")
    a.add_argument(
        "--no-select",
        action="store_true",
        help="keep the run's judge selection (default: SR and HFR come from judge 'learned' from now on)",
    )
    a.add_argument("--json", action="store_true", help="print the result as one JSON object on the last line")
    a.set_defaults(handler=_apply)

    sel = cmds.add_parser(
        "select",
        help="which judges' verdicts a run's SR and HFR come from",
        description="Record in RUN_DIR/judges/selection.json which judges count in SR and HFR (the others' rates "
        "stay in metrics.json judges.per_judge, on the same pairs), then write metrics.json and report.html again. "
        "'all': every judge with verdicts on both branches of a pair (the paper's formula). Without JUDGES: print "
        "the run's selection and the judges it has verdicts from.",
    )
    sel.add_argument("run_dir", type=Path, metavar="RUN_DIR", help="a paired run")
    sel.add_argument("judges", nargs="?", default=None, metavar="JUDGES", help="comma-separated judge ids, or 'all'")
    sel.add_argument("--rig", type=Path, default=None, help=RIG_HELP)
    sel.add_argument("--no-report", action="store_true", help="do not write metrics.json and report.html")
    sel.add_argument("--json", action="store_true", help="print the result as one JSON object on the last line")
    sel.set_defaults(handler=_select)

    s = cmds.add_parser("show", help="what a judge folder holds")
    s.add_argument("judge", type=Path, metavar="JUDGE", help="judge folder")
    s.add_argument("--json", action="store_true", help="print it as one JSON object on the last line")
    s.set_defaults(handler=_show)


def _roots(text: str) -> list[Path]:
    roots = [Path(x) for x in parse_list(text)]
    if not roots:
        raise ValueError("--data: expected at least one dataset folder")
    missing = [str(r) for r in roots if not r.is_dir()]
    if missing:
        raise ValueError(f"--data: {', '.join(missing)}: not a folder")
    return roots


def _rig(path: Path | None) -> RigConfig:
    from pilworld.config.rig import RigConfig
    from simrig.files import SIM_RIG

    return RigConfig.load(path or SIM_RIG)


def _train(args: argparse.Namespace) -> int:
    from pilworld.io.run_folder import JUDGE, check_out_folder
    from pilworld.judges.learned.folder import load_judge, provenance, save_judge
    from pilworld.judges.learned.labels import labelled_episodes
    from pilworld.judges.learned.train import TrainSettings, train_judge

    check_count(args.folds, "--folds", FOLDS)
    check_count(args.steps, "--steps", STEPS)
    check_count(args.seed, "--seed", SEED)
    if args.release_crop and not 8 <= args.release_crop <= 256:
        raise ValueError(f"--release-crop: expected 0 (off) or 8..256 pixels, got {args.release_crop}")
    if not 0 <= args.imagined <= 1:
        raise ValueError(f"--imagined: expected a share in 0..1, got {args.imagined}")
    if not 0 <= args.abstain_budget <= 0.9:
        raise ValueError(f"--abstain-budget: expected a share in 0..0.9, got {args.abstain_budget}")
    rig = _rig(args.rig)
    roots = _roots(args.data)
    if check_out_folder(args.out, JUDGE) == JUDGE:
        raise ValueError(f"--out: {args.out} already holds a judge; choose a new folder (or delete that one)")
    steps = {"steps": args.steps} if args.steps else {}
    settings = TrainSettings(
        folds=args.folds,
        seed=args.seed,
        release_crop=args.release_crop,
        imagined=args.imagined,
        abstain_budget=args.abstain_budget,
        **steps,
    )
    labelled = labelled_episodes(roots, args.labels)  # every input checked before anything is written
    n_yes = sum(lab.success for lab in labelled)
    print(f"judge train: {len(labelled)} labelled episodes ({n_yes} successes) from {len(roots)} dataset(s)")
    trained = train_judge(labelled, settings, progress=sys.stderr.isatty(), log=print, rig=rig)
    name = args.name or args.out.name
    save_judge(trained, args.out, provenance(labelled, args.labels), name)
    folder = load_judge(args.out)  # what was written reads back
    v = folder.validation
    print(
        f"judge {name!r} → {args.out}: out-of-fold agreement {v['accuracy_answered']:.1%} on the answered "
        f"{v['answered']} of {v['episodes']}, abstaining below confidence {folder.threshold:.2f} "
        f"({v['abstain_share']:.1%}); {v['seconds']['total']:.0f} s"
    )
    if args.json:
        print(json.dumps({"judge": str(args.out), "name": name, "threshold": folder.threshold, "validation": v}))
    return 0


def _evaluate(args: argparse.Namespace) -> int:
    from pilworld.judges.learned.evaluate import DEGRADATIONS, evaluate
    from pilworld.judges.learned.judge import LearnedSuccessJudge

    roots = _roots(args.data)
    judge = LearnedSuccessJudge(args.judge)
    result = evaluate(
        judge,
        roots,
        args.labels,
        degrade=DEGRADATIONS.get(args.degrade),
        progress=sys.stderr.isatty(),
        rig=_rig(args.rig),  # a release-crop judge reads the rig's kinematics and head camera
    )
    result = {"judge": str(args.judge), "labels": args.labels, "degrade": args.degrade or None, **result}
    agree = result["agreement"]
    print(
        f"judge {judge.folder.name!r} on {result['episodes']} episodes: agreement "
        f"{'n/a' if agree is None else f'{agree:.1%}'} on {result['answered']} answered, "
        f"{result['abstained']} abstained ({result['abstain_share']:.1%})"
    )
    for key, row in result["per_instruction"].items():
        a = row["agreement"]
        print(f"  {key[:60]:60s} {row['episodes']:4d} episodes  {'n/a' if a is None else f'{a:.1%}':>6s}"
              f"  abstained {row['abstained']}")  # fmt: skip
    if args.json:
        print(json.dumps(result))
    return 0


def _apply(args: argparse.Namespace) -> int:
    from pilworld.judges.learned.apply import apply_judge
    from pilworld.judges.learned.judge import LearnedSuccessJudge

    check_count(args.workers, "--workers", WORKERS)
    if not args.run_dir.is_dir():
        raise ValueError(f"RUN_DIR: {args.run_dir} is not a folder")
    judge = LearnedSuccessJudge(args.judge)
    rig = _rig(args.rig)
    select_as = None if args.no_select else "pilworld judge apply"
    result = apply_judge(
        judge, args.run_dir, rig, workers=args.workers, progress=sys.stderr.isatty(), select_as=select_as
    )
    if result.withdrawn:
        print(f"withdrew {result.withdrawn} verdicts of the judge applied before")
    print(
        f"judge {judge.folder.name!r} on {args.run_dir}: {result.judged} of {result.episodes} episodes judged, "
        f"{len(result.abstained)} left to people (pilworld annotate serve {args.run_dir} --abstained); "
        f"record {result.record}"
    )
    out: dict[str, Any] = {
        "judge": str(args.judge),
        "run_dir": str(args.run_dir),
        "episodes": result.episodes,
        "judged": result.judged,
        "abstained": result.abstained,
        "record": str(result.record),
    }
    if not args.no_select:
        from pilworld.data.judge_selection import SELECTION_FILE
        from pilworld.judges.learned.apply import LEARNED_ID

        print(f"SR and HFR of {args.run_dir} now come from judge {LEARNED_ID!r} ({args.run_dir / SELECTION_FILE}; "
              "pilworld judge select RUN_DIR all: every judge again)")  # fmt: skip
    out["selected"] = not args.no_select
    if not args.no_report:
        out |= rewrite_results(args.run_dir, rig)
    if args.json:
        print(json.dumps(out))
    return 0


def _select(args: argparse.Namespace) -> int:
    from pilworld.data.judge_selection import SELECTION_FILE, parse_judge_ids, read_selection, write_selection
    from pilworld.data.outcomes import judges_with_verdicts

    if not (args.run_dir / "meta" / "info.json").is_file():
        raise ValueError(f"RUN_DIR: {args.run_dir}: not a run folder (no meta/info.json)")
    have = judges_with_verdicts(args.run_dir)
    selection = read_selection(args.run_dir)
    if args.judges is not None:
        ids = parse_judge_ids(args.judges)
        unknown = [j for j in ids or () if j not in have]
        if unknown:
            raise ValueError(
                f"JUDGES: {', '.join(unknown)}: no verdicts of that judge in {args.run_dir} "
                f"(it has verdicts from: {', '.join(have) or 'no judge'})"
            )
        selection = write_selection(args.run_dir, ids, "pilworld judge select")
    chosen = "every judge with verdicts on both branches" if selection.judges is None else ", ".join(selection.judges)
    print(f"{args.run_dir}: SR and HFR come from {chosen} ({args.run_dir / SELECTION_FILE}, set by "
          f"{selection.set_by}); verdicts from: {', '.join(have) or 'no judge'}")  # fmt: skip
    out: dict[str, Any] = {"run_dir": str(args.run_dir), "selection": selection.as_json(), "judges_with_verdicts": have}
    if args.judges is not None and not args.no_report:
        out |= rewrite_results(args.run_dir, _rig(args.rig))
    if args.json:
        print(json.dumps(out))
    return 0


def rewrite_results(run_dir: Path, rig: RigConfig) -> dict[str, Any]:
    """metrics.json and report.html of a paired run written again, now with the learned verdicts."""
    from pilworld.data.pairs import is_paired
    from pilworld.data.reader import EpisodeStore
    from pilworld.metrics.report import METRICS_FILE, write_metrics
    from pilworld.report import build_report

    if not is_paired(EpisodeStore(run_dir)):
        print("not a paired run (no episode belongs to a pair): no metrics.json or report.html written")
        return {"metrics_json": None, "report_html": None}
    metrics = write_metrics(run_dir)
    report = build_report(run_dir, rig=rig)
    from pilworld.report.judges_view import judges_text

    print(f"metrics: {run_dir / METRICS_FILE}; report: {report}")
    print("\n".join(judges_text(metrics["judges"], metrics["overall"].get("sr_real_checker"))))
    return {"metrics_json": str(run_dir / METRICS_FILE), "report_html": str(report)}


def _show(args: argparse.Namespace) -> int:
    from pilworld.judges.learned.folder import CONFIG_FILE, load_judge

    folder = load_judge(args.judge)
    config = json.loads((folder.path / CONFIG_FILE).read_text())
    v = folder.validation
    print(f"judge {folder.name!r} ({folder.path}): {len(folder.nets)} networks, views {list(folder.spec.views)}")
    print(f"  trained on {folder.data.get('episodes')} episodes ({folder.data.get('labels')} labels) of "
          f"{len(folder.instructions)} instruction(s); abstains below confidence {folder.threshold:.2f}")  # fmt: skip
    if v:
        print(f"  out-of-fold agreement {v.get('accuracy_answered')} on {v.get('answered')} answered, "
              f"abstaining on {v.get('abstain_share')}")  # fmt: skip
    if args.json:
        print(json.dumps(config))
    return 0
