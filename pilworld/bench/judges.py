"""``pilworld bench judges``: how well the image-only success judge agrees with the privileged checker.

Runs :class:`~pilworld.judges.vision_success.VisionSuccessJudge` on every real-branch episode of a
collected dataset that carries the simulator checker's verdict (judge ``sim_checker`` in
``meta/outcomes.parquet``) and reports the agreement overall and per task, the confusion matrix per task
(``tp``: both say success, ``fp``: the judge says success and the checker failure, ``fn``: the other way
round, ``tn``: both say failure), the judge's seconds per episode (decoding the videos is timed apart),
and every disagreement with both sides' reasons. Nothing is written to the dataset.

The acceptance measurement (docs/judges.md, "Measured agreement") uses a fresh collection on seeds reserved
for judge validation::

    pilworld sim collect --task all --checkpoint all --episodes 3 --seed 3000000 --out /tmp/judge_val --workers 2

and then ``run_judge_bench("/tmp/judge_val", RigConfig.load("configs/rig/sim_dual_ur5e.yaml"))``.
"""

from __future__ import annotations

import argparse
import time
from collections.abc import Iterable
from pathlib import Path
from typing import Any

from pilworld.bench.common import machine_info
from pilworld.bench.flags import add_json, add_rig
from pilworld.bench.output import emit
from pilworld.config.rig import RigConfig
from pilworld.data.outcomes import read_outcomes
from pilworld.judges.base import Judge, JudgeContext, episode_task, worker_store
from pilworld.judges.vision_success import VisionSuccessJudge

CHECKER_ID = "sim_checker"  # the judge id pilworld.collection.collect records the checker's verdicts under


def _cell(judge: bool, checker: bool) -> str:
    if judge:
        return "tp" if checker else "fp"
    return "fn" if checker else "tn"


def _agreement(confusion: dict[str, int]) -> float | None:
    n = sum(confusion.values())
    return round((confusion["tp"] + confusion["tn"]) / n, 4) if n else None


def _judge_one(job: tuple[str, int, Judge, RigConfig]) -> tuple[int, Any, Any, float, float] | None:
    """(index, episode labels, verdict, load s, judge s) of one real-branch episode; None for an imagined one."""
    root, index, judge, rig = job
    t0 = time.perf_counter()
    ep = worker_store(root).load(index)
    t1 = time.perf_counter()
    if ep.origin != "real":
        return None
    verdict = judge.judge(ep, JudgeContext(rig=rig, task=episode_task(ep)))
    labels = (episode_task(ep), ep.subtask_index, ep.checkpoint, ep.seed, str(ep.extra.get("checker", "")))
    return index, labels, verdict, t1 - t0, time.perf_counter() - t1


def run_judge_bench(
    dataset_root: str | Path,
    rig: RigConfig,
    *,
    judge: Judge | None = None,
    episodes: Iterable[int] | None = None,
    progress: bool = False,
    workers: int = 1,
) -> dict[str, Any]:
    """Agreement of ``judge`` (default: the image-only success judge) with the checker on ``dataset_root``.

    Only real-branch episodes with a ``sim_checker`` verdict are judged (``episodes`` narrows them down),
    in ``workers`` processes (the seconds per episode are then summed over them, wall time apart).
    Returns a JSON-friendly dict: ``n``, ``agreement``, ``per_task`` (``n``, ``agreement``,
    ``confusion`` {tp, fp, fn, tn}), ``seconds_per_episode`` (judging), ``load_seconds_per_episode``
    (decoding), ``disagreements`` (one dict per episode: index, task, subtask, checkpoint, seed, both
    verdicts and reasons) and the machine it ran on. Raises ``ValueError`` if there is nothing to judge.
    """
    from pilworld.collection.workers import process_map, worker_count

    root = Path(dataset_root)
    judge = judge if judge is not None else VisionSuccessJudge()
    checker = {o.episode_index: o.success for o in read_outcomes(root) if o.judge_id == CHECKER_ID}
    wanted = sorted(checker) if episodes is None else [i for i in episodes if i in checker]
    per_task: dict[str, dict[str, int]] = {}
    disagreements: list[dict[str, Any]] = []
    judge_s = load_s = 0.0
    n = abstained = 0
    t_start = time.perf_counter()
    jobs = [(str(root), i, judge, rig) for i in wanted]
    for result in process_map(_judge_one, jobs, worker_count(workers, len(jobs))):
        if result is None:
            continue
        i, (task, subtask, checkpoint, seed, checker_reason), verdict, t_load, t_judge = result
        load_s += t_load
        judge_s += t_judge
        if verdict.success is None:  # a learned judge abstains: the episode goes to people, not to its score
            abstained += 1
            continue
        n += 1
        said, truth = bool(verdict.success), bool(checker[i])
        confusion = per_task.setdefault(task, {"tp": 0, "fp": 0, "fn": 0, "tn": 0})
        confusion[_cell(said, truth)] += 1
        if said != truth:
            disagreements.append(
                {
                    "episode_index": i,
                    "task": task,
                    "subtask_index": subtask,
                    "checkpoint": checkpoint,
                    "seed": seed,
                    "checker": truth,
                    "checker_reason": checker_reason,
                    "judge": said,
                    "judge_reason": verdict.reason,
                }
            )
        if progress:
            print(f"episode {i}: {task} subtask {subtask}: judge {said}, checker {truth}", flush=True)
    if n + abstained == 0:  # a judge that abstained on every episode still reports that (agreement None)
        raise ValueError(f"{root}: no real-branch episodes with a {CHECKER_ID!r} verdict to judge")
    total = {k: sum(c[k] for c in per_task.values()) for k in ("tp", "fp", "fn", "tn")}
    return {
        "judge_id": judge.judge_id,
        "dataset": str(root),
        "n": n,
        "abstained": abstained,
        "agreement": _agreement(total),
        "confusion": total,
        "per_task": {
            task: {"n": sum(c.values()), "agreement": _agreement(c), "confusion": c}
            for task, c in sorted(per_task.items())
        },
        "seconds_per_episode": round(judge_s / (n + abstained), 3),
        "load_seconds_per_episode": round(load_s / (n + abstained), 3),
        "wall_seconds": round(time.perf_counter() - t_start, 1),
        "disagreements": disagreements,
        "machine": machine_info(),
    }


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        "dataset", type=Path, help="a dataset with sim_checker verdicts (e.g. from pilworld sim collect)"
    )
    parser.add_argument(
        "--judge",
        type=Path,
        default=None,
        help="a learned judge folder (pilworld judge train); default: the paper tasks' hand-written reference",
    )
    parser.add_argument("--workers", type=int, default=1, help="processes judging episodes (default 1)")
    add_rig(parser)
    add_json(parser)


def run(args: argparse.Namespace) -> int:
    """The agreement overall and per task with its confusion matrix."""
    from pilworld.options.bounds import WORKERS, check_count

    check_count(args.workers, "--workers", WORKERS)
    judge: Judge | None = None
    if args.judge is not None:
        from pilworld.judges.learned.judge import LearnedSuccessJudge

        judge = LearnedSuccessJudge(args.judge)
    r = run_judge_bench(
        args.dataset, RigConfig.load(args.rig), judge=judge, progress=not args.json, workers=args.workers
    )
    lines = [
        f"judges: {r['judge_id']} agrees with the checker on {r['agreement']} of {r['n']} real episodes"
        + (f" ({r['abstained']} abstained)" if r["abstained"] else "")
    ]
    lines += [
        f"  {task}: {t['agreement']} of {t['n']}, confusion {t['confusion']}" for task, t in r["per_task"].items()
    ]
    return emit(args, r, lines)
