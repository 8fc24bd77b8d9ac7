"""How the human judges agree with each other and with the automatic judges (``metrics.json`` ``human_agreement``).

Human judges are the outcomes rows with ids ``human_<n>`` (what ``pilworld annotate export`` writes);
every other judge (the simulator's checker ``sim_checker``, the image judge ``vision``, a hardware
run's ``operator``) is a reference they are compared with.

* **Success, between humans**: Fleiss' κ over the episodes labelled by two or more humans, with
  categories success / failure. Episodes may have different numbers of raters (judges labelling
  subsets); Fleiss' per-item agreement P_i = (Σ_j n_ij² − n_i) / (n_i (n_i − 1)) allows that, and
  category shares p_j are pooled over all ratings. κ is undefined (None with a reason) without such
  episodes or when every rating falls in one category (P_e = 1).
* **First hallucination frame, between humans**: per episode with ≥ 2 humans, whether all said "none",
  all marked a frame, or they split (also as Fleiss' κ on presence); where ≥ 2 marked a frame, the
  spread of their frames: median absolute deviation from the median and the range (max − min), in
  frames. Given for all episodes and per origin (a real episode should show no hallucination).
* **Humans vs each other judge**: per human and reference judge, on the episodes both judged, the
  share of equal success verdicts and Cohen's κ; for references that mark hallucinations (not the
  simulator's checker) also the share agreeing on presence and the median |Δ frame| where both marked.
* **human_only**: SR_real, SR_imag, |ΔSR| and HFR from the human verdicts alone (the paper's figures
  come from human judges), by task and overall, with the same rules as the run's metrics.
"""

from __future__ import annotations

import re
from collections import defaultdict
from collections.abc import Mapping, Sequence
from dataclasses import replace
from typing import Any

import numpy as np

from pilworld.data.outcomes import Outcome
from pilworld.data.pairs import PairedEpisodes
from pilworld.metrics.bootstrap import DEFAULT_RESAMPLES, DEFAULT_SEED
from pilworld.metrics.success import CHECKER_KIND, group_metrics, score_pairs

HUMAN_ID = re.compile(r"human_\d+")
NO_SHARED = "no episode was labelled by two or more human judges"
ONE_CATEGORY = "every rating is in one category, so chance agreement is 1 and κ is undefined"


def is_human(judge_id: str) -> bool:
    return HUMAN_ID.fullmatch(judge_id) is not None


def _human_sort_key(judge_id: str) -> tuple[int, str]:
    return (int(judge_id.split("_")[1]), judge_id) if is_human(judge_id) else (0, judge_id)


def fleiss_kappa(counts: Sequence[Sequence[int]]) -> tuple[float | None, str | None, dict[str, float]]:
    """Fleiss' κ of a table ``counts[item][category]`` (raters per item may differ, each item ≥ 2).

    Returns (κ or None, reason when None, {"observed": P̄, "chance": P_e}).
    """
    table = np.asarray(counts, dtype=np.float64)
    if table.size == 0:
        return None, NO_SHARED, {}
    if table.ndim != 2 or (table < 0).any():
        raise ValueError(f"counts: expected a non-negative (items, categories) table, got shape {table.shape}")
    n = table.sum(axis=1)
    if (n < 2).any():
        raise ValueError("counts: every item needs two or more ratings")
    p_i = ((table**2).sum(axis=1) - n) / (n * (n - 1))
    p_j = table.sum(axis=0) / n.sum()
    observed, chance = float(p_i.mean()), float((p_j**2).sum())
    stats = {"observed": observed, "chance": chance}
    if chance >= 1.0 - 1e-12:
        return None, ONE_CATEGORY, stats
    return (observed - chance) / (1.0 - chance), None, stats


def cohen_kappa(a: Sequence[bool], b: Sequence[bool]) -> tuple[float | None, str | None]:
    """Cohen's κ of two raters' binary verdicts on the same items."""
    if not a:
        return None, "no episodes judged by both"
    x, y = np.asarray(a, dtype=bool), np.asarray(b, dtype=bool)
    observed = float((x == y).mean())
    chance = float(x.mean() * y.mean() + (1 - x.mean()) * (1 - y.mean()))
    if chance >= 1.0 - 1e-12:
        return None, ONE_CATEGORY
    return (observed - chance) / (1.0 - chance), None


def mad(values: Sequence[float]) -> float:
    """Median absolute deviation from the median."""
    v = np.asarray(values, dtype=np.float64)
    return float(np.median(np.abs(v - np.median(v))))


def _kappa_entry(prefix: str, counts: list[list[int]]) -> dict[str, Any]:
    kappa, reason, stats = fleiss_kappa(counts)
    out: dict[str, Any] = {prefix: kappa}
    if reason:
        out[f"{prefix}_reason"] = reason
    out["observed_agreement"] = stats.get("observed")
    out["chance_agreement"] = stats.get("chance")
    return out


def _success(shared: Mapping[int, list[Outcome]]) -> dict[str, Any]:
    counts = [[sum(o.success for o in v), sum(not o.success for o in v)] for v in shared.values()]
    raters = [len(v) for v in shared.values()]
    return {
        "episodes": len(shared),
        **_kappa_entry("fleiss_kappa", counts),
        "unanimous_share": float(np.mean([0 in c for c in counts])) if counts else None,
        "raters_per_episode": {"min": min(raters), "max": max(raters)} if raters else None,
    }


def _hallucination(shared: Mapping[int, list[Outcome]]) -> dict[str, Any]:
    out: dict[str, Any] = {"episodes": len(shared)}
    marks = [[o.first_hallucination_frame for o in v] for v in shared.values()]
    if not marks:
        return out | {"agree_none_share": None, "agree_some_share": None, "reason": NO_SHARED}
    out["agree_none_share"] = float(np.mean([all(f is None for f in m) for m in marks]))
    out["agree_some_share"] = float(np.mean([all(f is not None for f in m) for m in marks]))
    counts = [[sum(f is not None for f in m), sum(f is None for f in m)] for m in marks]
    presence = _kappa_entry("presence_fleiss_kappa", counts)
    out["presence_fleiss_kappa"] = presence["presence_fleiss_kappa"]
    if "presence_fleiss_kappa_reason" in presence:
        out["presence_fleiss_kappa_reason"] = presence["presence_fleiss_kappa_reason"]
    frames = [[float(f) for f in m if f is not None] for m in marks]
    frames = [f for f in frames if len(f) >= 2]
    spread: dict[str, Any] = {"episodes": len(frames)}
    if frames:
        mads, ranges = [mad(f) for f in frames], [max(f) - min(f) for f in frames]
        spread |= {
            "mad_median": float(np.median(mads)),
            "mad_mean": float(np.mean(mads)),
            "range_median": float(np.median(ranges)),
            "range_mean": float(np.mean(ranges)),
            "range_max": float(np.max(ranges)),
        }
    else:
        spread["reason"] = "no episode has a hallucination frame from two or more human judges"
    out["frame_spread"] = spread
    return out


def _versus(human: list[Outcome], other: list[Outcome], other_kind: str) -> dict[str, Any]:
    """One human vs one reference judge over the episodes both judged."""
    theirs = {o.episode_index: o for o in other}
    both = [(o, theirs[o.episode_index]) for o in human if o.episode_index in theirs]
    a, b = [h.success for h, _ in both], [r.success for _, r in both]
    kappa, reason = cohen_kappa(a, b)
    out: dict[str, Any] = {
        "kind": other_kind,
        "episodes": len(both),
        "success_agreement": float(np.mean(np.equal(a, b))) if both else None,
        "success_cohen_kappa": kappa,
    }
    if reason:
        out["success_cohen_kappa_reason"] = reason
    if other_kind != CHECKER_KIND:  # the simulator's checker never marks hallucinations
        hp = [(h.first_hallucination_frame, r.first_hallucination_frame) for h, r in both]
        out["hallucination_presence_agreement"] = (
            float(np.mean([(x is None) == (y is None) for x, y in hp])) if hp else None
        )
        diffs = [abs(x - y) for x, y in hp if x is not None and y is not None]
        out["frame_pairs"] = len(diffs)
        out["frame_abs_diff_median"] = float(np.median(diffs)) if diffs else None
    return out


def _human_only(paired: PairedEpisodes, bootstrap: int, seed: int) -> dict[str, Any]:
    verdicts = {e: [o for o in v if is_human(o.judge_id)] for e, v in paired.verdicts.items()}
    scores = score_pairs(replace(paired, verdicts=verdicts))
    by_task: dict[str, list[Any]] = defaultdict(list)
    for s in scores:
        by_task[s.pair.task].append(s)
    drop = ("sr_real_checker", "sr_real_checker_reason", "n_checker")  # no checker among humans
    tasks = {
        t: {k: v for k, v in group_metrics(g, bootstrap=bootstrap, seed=seed).items() if k not in drop}
        for t, g in sorted(by_task.items())
    }
    overall = {k: v for k, v in group_metrics(scores, bootstrap=bootstrap, seed=seed).items() if k not in drop}
    return {"tasks": tasks, "overall": overall}


def human_agreement(
    paired: PairedEpisodes,
    origins: Mapping[int, str],
    *,
    bootstrap: int = DEFAULT_RESAMPLES,
    seed: int = DEFAULT_SEED,
) -> dict[str, Any]:
    """The ``human_agreement`` block of metrics.json (see the module docstring); ``origins``: episode → origin."""
    by_episode: dict[int, list[Outcome]] = defaultdict(list)
    by_judge: dict[str, list[Outcome]] = defaultdict(list)
    for episode, verdicts in paired.verdicts.items():
        for o in verdicts:
            by_judge[o.judge_id].append(o)
            if is_human(o.judge_id):
                by_episode[episode].append(o)
    humans = sorted((j for j in by_judge if is_human(j)), key=_human_sort_key)
    if not humans:
        return {"judges": [], "reason": "no human verdicts (pilworld annotate export writes human_1 … human_N)"}
    shared = {e: v for e, v in sorted(by_episode.items()) if len(v) >= 2}
    hallucination = {"all": _hallucination(shared)}
    for origin in sorted({origins.get(e, "") for e in shared} - {""}):
        hallucination[origin] = _hallucination({e: v for e, v in shared.items() if origins.get(e) == origin})
    references = sorted(j for j in by_judge if not is_human(j))
    versus = {h: {r: _versus(by_judge[h], by_judge[r], by_judge[r][0].judge_kind) for r in references} for h in humans}
    return {
        "judges": humans,
        "episodes_labelled": {h: len(by_judge[h]) for h in humans},
        "episodes_shared": len(shared),
        "success": _success(shared),
        "hallucination": hallucination,
        "vs_other_judges": versus,
        "human_only": _human_only(paired, bootstrap, seed),
    }
