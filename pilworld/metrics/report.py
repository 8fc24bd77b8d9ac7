"""``metrics.json`` of a paired run: success agreement, HFR, ranking agreement and single-step image error.

``compute_run_metrics(root)`` reads the run's dataset and outcomes table and returns one
JSON-serialisable dict (layout in docs/metrics.md); ``write_metrics(root)`` writes it to
``root/metrics.json``. Every value that cannot be computed is ``None`` with a ``<key>_reason`` beside it.
"""

from __future__ import annotations

import argparse
import math
from collections import defaultdict
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from pilworld.data.judge_selection import read_selection
from pilworld.data.pairs import load_pairs
from pilworld.data.reader import EpisodeStore
from pilworld.io.atomic import write_json
from pilworld.metrics.bootstrap import DEFAULT_RESAMPLES, DEFAULT_SEED, LEVEL
from pilworld.metrics.ranking import ranking_metrics
from pilworld.metrics.ranking_ci import ranking_intervals
from pilworld.metrics.single_step import DEFAULT_ACTION_ATOL, single_step_metrics
from pilworld.metrics.success import PairScore, group_metrics, judge_summary, no_common_judge_reason, score_pairs

METRICS_FILE = "metrics.json"
FORMAT = "pilworld.metrics/v1"
SIGNIFICANT = 6  # digits kept: more than the paper reports, fewer than float noise (and 1e-05 survives)


def rounded(value: Any, digits: int = SIGNIFICANT) -> Any:
    """``value`` with every float rounded to ``digits`` significant digits; a non-finite float raises."""
    if isinstance(value, float):
        if not math.isfinite(value):
            raise ValueError(f"metrics: non-finite value {value!r} (undefined values must be None with a reason)")
        return float(f"{value:.{digits}g}")
    if isinstance(value, dict):
        return {k: rounded(v, digits) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [rounded(v, digits) for v in value]
    return value


def _task_mean(tasks: dict[str, dict[str, Any]], key: str) -> tuple[float | None, str | None]:
    values = [t[key] for t in tasks.values() if t[key] is not None]
    if not values:
        return None, f"no task has {key}"
    return sum(values) / len(values), None


def _ranking(settings: Sequence[dict[str, Any]]) -> dict[str, Any]:
    ranked = [s for s in settings if s["sr_real"] is not None and s["sr_imag"] is not None]
    out = ranking_metrics([s["sr_imag"] for s in ranked], [s["sr_real"] for s in ranked])
    return {**out, "n_settings_ranked": len(ranked)}


def compute_run_metrics(
    root: str | Path,
    *,
    bootstrap: int = DEFAULT_RESAMPLES,
    seed: int = DEFAULT_SEED,
    single_step: bool = True,
    action_atol: float = DEFAULT_ACTION_ATOL,
    lpips: bool = True,
) -> dict[str, Any]:
    """All metrics of the paired run at ``root`` (see docs/metrics.md for every key).

    ``bootstrap`` resamples (0 = no intervals) with ``seed``; ``single_step=False`` skips the image
    metrics (they decode round 0 of every pair); ``action_atol`` is the round-0 action tolerance of the
    single-step check; ``lpips=False`` skips loading LPIPS.
    """
    store = EpisodeStore(root)
    paired = load_pairs(root, store)
    selection = read_selection(root)
    scores = score_pairs(paired, selection)
    why = no_common_judge_reason(selection)
    by_task: dict[str, list[PairScore]] = defaultdict(list)
    by_setting: dict[tuple[str, str], list[PairScore]] = defaultdict(list)
    for s in scores:
        by_task[s.pair.task].append(s)
        by_setting[s.pair.setting].append(s)

    settings = []
    for (task, ckpt), group in sorted(by_setting.items()):
        m = group_metrics(group, bootstrap=0, no_judge_reason=why)
        m.pop("ci95")
        settings.append({"task": task, "checkpoint": ckpt, **m, "n": m["n_subtasks"]})

    tasks: dict[str, dict[str, Any]] = {}
    for task, group in sorted(by_task.items()):
        tasks[task] = group_metrics(group, bootstrap=bootstrap, seed=seed, no_judge_reason=why)
        across = _ranking([s for s in settings if s["task"] == task])
        tasks[task]["across_checkpoints"] = across

    overall = group_metrics(scores, bootstrap=bootstrap, seed=seed, no_judge_reason=why)
    for key in ("abs_delta_sr", "hfr"):
        value, reason = _task_mean(tasks, key)
        overall[f"{key}_task_mean"] = value
        if reason:
            overall[f"{key}_task_mean_reason"] = reason
    overall |= _ranking(settings)
    overall["ranking_ci95"] = ranking_intervals(scores, resamples=bootstrap, seed=seed) if bootstrap else None
    overall["n_settings"] = len(settings)
    overall["n_tasks"] = len(tasks)

    out: dict[str, Any] = {
        "format": FORMAT,
        "run": {
            "root": str(store.root),
            "episodes": store.num_episodes,
            "pairs": len(paired.pairs),
            "incomplete_pairs": paired.incomplete,
            "unpaired_episodes": paired.unpaired_episodes,
        },
        "tasks": tasks,
        "settings": settings,
        "overall": overall,
        "judges": judge_summary(paired, scores, selection) | {"learned": applied_judge(root)},
        "bootstrap": {
            "resamples": bootstrap,
            "seed": seed,
            "level": LEVEL,
            "method": "percentile; pairs (subtasks) resampled with replacement within each task and overall",
        },
    }
    from pilworld.metrics.agreement import human_agreement  # here: annotate imports pilworld.metrics

    origins = {int(r["episode_index"]): str(r.get("origin") or "") for r in store.episodes}
    out["human_agreement"] = human_agreement(paired, origins, bootstrap=bootstrap, seed=seed)
    from pilworld.ppi.section import ppi_section  # real success rates by PPI++ with the attached imagined-only runs

    out["ppi"] = ppi_section(root)
    if single_step:
        out["single_step"] = single_step_metrics(store, paired.pairs, action_atol=action_atol, lpips=lpips)
    else:
        out["single_step"] = {"reason": "disabled by the caller"}
    result: dict[str, Any] = rounded(out)
    return result


def applied_judge(root: str | Path) -> dict[str, Any] | None:
    """Which learned judge gave the run's ``learned`` verdicts (``pilworld judge apply``), with its validation
    figures and how many episodes it left to people; None when none was applied."""
    from pilworld.judges.learned.apply import read_record

    record = read_record(root)
    if record is None:
        return None
    keep = ("name", "folder", "sha256", "threshold", "validation", "trained_on", "episodes", "judged", "complete")
    abstained = record.get("abstained")
    return {k: record.get(k) for k in keep} | {"abstained": None if abstained is None else len(abstained)}


def write_metrics(root: str | Path, out_path: str | Path | None = None, **kwargs: Any) -> dict[str, Any]:
    """Compute the run's metrics and write them (default ``root/metrics.json``); returns the dict."""
    metrics = compute_run_metrics(root, **kwargs)
    path = Path(out_path) if out_path is not None else Path(root) / METRICS_FILE
    write_json(path, metrics)
    return metrics


def main(argv: Sequence[str] | None = None) -> int:
    """``python -m pilworld.metrics.report RUN [--out FILE] [--bootstrap N] [--seed S] [--no-single-step]``."""
    parser = argparse.ArgumentParser(prog="python -m pilworld.metrics.report", description=__doc__)
    parser.add_argument("run", type=Path, help="a paired run folder")
    parser.add_argument("--out", type=Path, default=None, help="output file (default RUN/metrics.json)")
    parser.add_argument("--bootstrap", type=int, default=DEFAULT_RESAMPLES, help="resamples, 0 = no intervals")
    parser.add_argument("--seed", type=int, default=DEFAULT_SEED)
    parser.add_argument("--no-single-step", action="store_true", help="skip the image metrics")
    args = parser.parse_args(argv)
    path = args.out or args.run / METRICS_FILE
    write_metrics(args.run, path, bootstrap=args.bootstrap, seed=args.seed, single_step=not args.no_single_step)
    print(path)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
