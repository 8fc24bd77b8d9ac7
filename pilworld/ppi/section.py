"""The ``ppi`` section of ``metrics.json``: each checkpoint's real success rate by PPI++, beside the classical one.

Per checkpoint (and per task × checkpoint): the classical interval from the n paired subtasks' real
outcomes alone, the prediction-powered interval from those plus the N imagined-only branches, the
power-tuning λ, and the effective sample size gain (how many real trials each real trial is worth once
the imagined ones are added). Then intervals of every checkpoint difference, for ranking: a difference
whose interval excludes 0 separates the two checkpoints at the 95 % level.
"""

from __future__ import annotations

from itertools import combinations
from pathlib import Path
from typing import Any

from pilworld.ppi.estimator import DEFAULT_ALPHA, PPIEstimate, classical_mean, difference, ppi_mean
from pilworld.ppi.outcomes import CheckpointOutcomes, RunOutcomes, read_run_outcomes

NO_IMAGINED = "no imagined-only runs attached (pilworld imagine, then pilworld report RUN --imagined DIR)"


class PPIInputError(ValueError):
    """Outcomes PPI cannot use (a checkpoint without paired subtasks, …), named in one line."""


def _estimate(
    name: str, o: CheckpointOutcomes, *, alpha: float, method: str
) -> tuple[dict[str, Any], PPIEstimate | None]:
    entry: dict[str, Any] = {"n": len(o.y), "N": len(o.unlabeled), "gold_judges": sorted(o.gold_judges)}
    if o.skipped_pairs:
        entry["pairs_without_verdicts"] = o.skipped_pairs
    if not o.y:
        entry["reason"] = f"{name}: no paired subtasks (n = 0); PPI needs real outcomes of this checkpoint"
        return entry, None
    if not o.unlabeled:
        entry["classical"] = classical_mean(o.y, alpha=alpha, method=method).to_json()
        entry["reason"] = NO_IMAGINED
        return entry, None
    est = ppi_mean(o.y, o.f, o.unlabeled, alpha=alpha, method=method)
    entry |= est.to_json()
    entry["real_trials_saved"] = round(len(o.y) * (est.ess_gain - 1.0), 1)
    return entry, est


def check_outcomes(outcomes: RunOutcomes) -> None:
    """Refuse imagined-only branches of a checkpoint the paired run never ran (n = 0), naming it."""
    for ckpt, o in sorted(outcomes.by_checkpoint.items()):
        if o.unlabeled and not o.y:
            raise PPIInputError(
                f"checkpoint {ckpt}: {len(o.unlabeled)} imagined-only branches but no paired subtasks (n = 0); "
                "PPI needs some real outcomes of each checkpoint it estimates"
            )


def ppi_section(
    root: str | Path,
    imagined: list[str] | None = None,
    *,
    alpha: float = DEFAULT_ALPHA,
    method: str = "wilson",
    gold: str | None = None,
    proxy: str | None = None,
    strict: bool = False,
) -> dict[str, Any]:
    """The section for the paired run at ``root``; ``strict`` raises :class:`PPIInputError` on bad input."""
    outcomes = read_run_outcomes(root, imagined, gold=gold, proxy=proxy)
    if strict:
        check_outcomes(outcomes)
    checkpoints: dict[str, Any] = {}
    estimates: dict[str, PPIEstimate] = {}
    for ckpt, o in sorted(outcomes.by_checkpoint.items()):
        checkpoints[ckpt], est = _estimate(f"checkpoint {ckpt}", o, alpha=alpha, method=method)
        if est is not None:
            estimates[ckpt] = est
    settings = []
    for (task, ckpt), o in sorted(outcomes.by_setting.items()):
        entry, _ = _estimate(f"{task} × {ckpt}", o, alpha=alpha, method=method)
        settings.append({"task": task, "checkpoint": ckpt, **entry})
    ranked = sorted(estimates, key=lambda c: -estimates[c].ppi.estimate)
    differences = []
    for a, b in combinations(ranked, 2):
        d_ppi = difference(estimates[a], estimates[b], "ppi")
        d_cl = difference(estimates[a], estimates[b], "classical")
        differences.append(
            {
                "a": a,
                "b": b,
                "ppi": d_ppi.to_json(),
                "classical": d_cl.to_json(),
                "separated_ppi": d_ppi.lower > 0 or d_ppi.upper < 0,
                "separated_classical": d_cl.lower > 0 or d_cl.upper < 0,
            }
        )
    gains = [e.ess_gain for e in estimates.values()]
    return {
        "method": method,
        "alpha": alpha,
        "proxy_judge": outcomes.proxy,
        "gold_judge": gold or "auto (sim_checker, else operator, else human labels, else the proxy judge)",
        "imagined_runs": outcomes.imagined_runs,
        "imagined_overlapping_paired": outcomes.overlapping,
        "checkpoints": checkpoints,
        "settings": settings,
        "ranking": ranked,
        "differences": differences,
        "mean_ess_gain": round(sum(gains) / len(gains), 4) if gains else None,
        "reason": None if estimates else NO_IMAGINED,
    }
