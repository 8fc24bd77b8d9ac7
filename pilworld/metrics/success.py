"""Success rates of both branches, |ΔSR| and the hallucination-free ratio (paper appendix "Metric Definitions").

Paper: with N subtasks each judged by M judges,
SR_b = (1/M) Σ_m (1/N) Σ_i y_b^(i,m) for b ∈ {real, imag}, |ΔSR| = |SR_imag − SR_real|, and
HFR = (1/M) Σ_m (1/N) Σ_i t_h^(i,m) / T_i  (t_h = T_i when judge m saw no hallucination).

**Which judges.** The success rates of a pair come from the judges that gave a verdict on *both* of
its branches, so SR_real and SR_imag are measured by the same judges. A pair's branch score is the
mean success over those judges, and SR is the mean over pairs. When every judge judged every pair this
is exactly the paper's formula; when judges covered different pairs (people labelling a subset), each
pair is weighted once rather than each verdict. The simulator's privileged checker (kind
``sim_state``) sees only real episodes, so it never enters SR_real; its rate is reported apart as
``sr_real_checker``. Pairs without a common judge are left out of SR and counted.

**Selected judges.** A run may name the judges that count (:mod:`pilworld.data.judge_selection`,
``RUN_DIR/judges/selection.json``): then only their verdicts enter SR and HFR, and every judge's own
rates stay in ``judges.per_judge``.

**HFR** is over imagined episodes: a pair's value is the mean of t_h / T over every non-``sim_state``
verdict on its imagined episode (a verdict whose ``first_hallucination_frame`` is null means the
judge saw none: t_h = T, per the outcomes table), and HFR is the mean over pairs that have one.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from pilworld.data.judge_selection import DEFAULT, JudgeSelection
from pilworld.data.outcomes import Outcome
from pilworld.data.pairs import Pair, PairedEpisodes
from pilworld.metrics.bootstrap import DEFAULT_RESAMPLES, DEFAULT_SEED, bootstrap_means

CHECKER_KIND = "sim_state"  # privileged simulator checkers: real episodes only, reported apart

NO_COMMON_JUDGE = (
    "no judge gave verdicts on both branches of these pairs (the simulator's checker judges only real "
    "episodes); run an image-only or human judge on both branches"
)
NO_HALLUCINATION_VERDICT = "no verdicts on the imagined episodes of these pairs"
NO_CHECKER = "no sim_state verdicts on the real episodes of these pairs"


@dataclass(frozen=True)
class PairScore:
    """The per-pair values every aggregate is a mean of (None = no verdict of that kind)."""

    pair: Pair
    real: float | None  # mean success of the real branch over the both-branch judges
    imag: float | None  # mean success of the imagined branch over the same judges
    judges: tuple[str, ...]  # the both-branch judges
    checker: float | None  # mean success of the real branch by sim_state judges
    hfr: float | None  # mean t_h / T of the imagined branch over its hallucination verdicts
    hfr_judges: tuple[str, ...]


def _mean(values: Sequence[float]) -> float | None:
    return float(np.mean(values)) if values else None


def score_pair(pair: Pair, paired: PairedEpisodes, selection: JudgeSelection = DEFAULT) -> PairScore:
    """The pair's values; only the judges ``selection`` allows count in SR and HFR (the checker always apart)."""
    real = {o.judge_id: o for o in paired.outcomes(pair.real)}
    imag = {o.judge_id: o for o in paired.outcomes(pair.imagined)}
    common = tuple(sorted(j for j in set(real) & set(imag) if selection.allows(j)))
    hallucination: list[Outcome] = [
        o for o in imag.values() if o.judge_kind != CHECKER_KIND and selection.allows(o.judge_id)
    ]
    return PairScore(
        pair=pair,
        real=_mean([float(real[j].success) for j in common]),
        imag=_mean([float(imag[j].success) for j in common]),
        judges=common,
        checker=_mean([float(o.success) for o in real.values() if o.judge_kind == CHECKER_KIND]),
        hfr=_mean([o.hallucination_free_fraction for o in hallucination]),
        hfr_judges=tuple(sorted(o.judge_id for o in hallucination)),
    )


def score_pairs(paired: PairedEpisodes, selection: JudgeSelection = DEFAULT) -> list[PairScore]:
    return [score_pair(p, paired, selection) for p in paired.pairs]


def _column(scores: Sequence[PairScore], name: str) -> np.ndarray[Any, np.dtype[np.float64]]:
    return np.array([np.nan if getattr(s, name) is None else getattr(s, name) for s in scores], dtype=np.float64)


def no_common_judge_reason(selection: JudgeSelection) -> str:
    """Why a group has no SR: no both-branch judge at all, or none among the selected ones."""
    if selection.judges is None:
        return NO_COMMON_JUDGE
    return (
        f"none of the selected judges ({', '.join(selection.judges)}) gave verdicts on both branches of these "
        "pairs (the run's judges/selection.json; pilworld judge select RUN_DIR all: every judge counts)"
    )


def group_metrics(
    scores: Sequence[PairScore],
    *,
    bootstrap: int = DEFAULT_RESAMPLES,
    seed: int = DEFAULT_SEED,
    no_judge_reason: str = NO_COMMON_JUDGE,
) -> dict[str, Any]:
    """SR_real, SR_imag, ΔSR = SR_imag − SR_real, |ΔSR|, HFR, sr_real_checker of a group of pairs.

    Also ``n_subtasks`` (pairs), ``n_judged`` (pairs with a both-branch judge), ``n_hfr``,
    ``n_checker``, a ``*_reason`` for every ``None``, and ``ci95`` (bootstrap over the group's pairs;
    ``None`` when ``bootstrap`` is 0 or the group is empty).
    """
    cols = {name: _column(scores, name) for name in ("real", "imag", "checker", "hfr")}
    judged = np.isfinite(cols["real"])

    def mean(name: str) -> float | None:
        v = cols[name][np.isfinite(cols[name])]
        return float(v.mean()) if v.size else None

    out: dict[str, Any] = {
        "sr_real": mean("real"),
        "sr_imag": mean("imag"),
        "delta_sr": None,
        "abs_delta_sr": None,
        "hfr": mean("hfr"),
        "sr_real_checker": mean("checker"),
        "n_subtasks": len(scores),
        "n_judged": int(judged.sum()),
        "n_hfr": int(np.isfinite(cols["hfr"]).sum()),
        "n_checker": int(np.isfinite(cols["checker"]).sum()),
    }
    if out["sr_real"] is not None and out["sr_imag"] is not None:
        out["delta_sr"] = out["sr_imag"] - out["sr_real"]
        out["abs_delta_sr"] = abs(out["delta_sr"])
    else:
        for key in ("sr_real", "sr_imag", "delta_sr", "abs_delta_sr"):
            out[f"{key}_reason"] = no_judge_reason
    if out["hfr"] is None:
        out["hfr_reason"] = NO_HALLUCINATION_VERDICT
    if out["sr_real_checker"] is None:
        out["sr_real_checker_reason"] = NO_CHECKER
    out["ci95"] = None
    if bootstrap and scores:
        ci = bootstrap_means(
            {"sr_real": cols["real"], "sr_imag": cols["imag"], "hfr": cols["hfr"], "sr_real_checker": cols["checker"]},
            differences={"delta_sr": ("sr_imag", "sr_real")},
            resamples=bootstrap,
            seed=seed,
        )
        out["ci95"] = ci
    return out


def judge_summary(
    paired: PairedEpisodes, scores: Sequence[PairScore], selection: JudgeSelection = DEFAULT
) -> dict[str, Any]:
    """Which judges were used for what, with counts, per-judge rates and agreement with the checker.

    ``per_judge[j]``: its kind; ``pairs_both`` (pairs it judged on both branches, i.e. where it counts
    in SR), ``real_only`` / ``imagined_only`` (pairs it judged on one branch), its own ``sr_real`` /
    ``sr_imag`` over its both-branch pairs, its ``hfr`` over its imagined verdicts, and
    ``agreement_with_checker``: the fraction of real episodes where its success verdict equals the
    sim_state checker's (None without a checker verdict on those episodes).
    """
    per: dict[str, dict[str, Any]] = {}
    for p in paired.pairs:
        real = {o.judge_id: o for o in paired.outcomes(p.real)}
        imag = {o.judge_id: o for o in paired.outcomes(p.imagined)}
        checker = [o.success for o in real.values() if o.judge_kind == CHECKER_KIND]
        for jid in set(real) | set(imag):
            o = real.get(jid) or imag[jid]
            d = per.setdefault(jid, {"kind": o.judge_kind, "pairs_both": 0, "real_only": 0, "imagined_only": 0})
            for key in ("_sr", "_hfr", "_agree"):  # working lists, replaced by means below
                d.setdefault(key, [])
            if jid in real and jid in imag:
                d["pairs_both"] += 1
                d["_sr"].append((float(real[jid].success), float(imag[jid].success)))
            elif jid in real:
                d["real_only"] += 1
            else:
                d["imagined_only"] += 1
            if jid in imag and imag[jid].judge_kind != CHECKER_KIND:
                d["_hfr"].append(imag[jid].hallucination_free_fraction)
            if jid in real and real[jid].judge_kind != CHECKER_KIND and len(set(checker)) == 1:
                d["_agree"].append(float(real[jid].success == checker[0]))  # checkers that disagree: skipped
    for d in per.values():
        sr, hfr, agree = d.pop("_sr"), d.pop("_hfr"), d.pop("_agree")
        d["sr_real"] = _mean([a for a, _ in sr])
        d["sr_imag"] = _mean([b for _, b in sr])
        d["hfr"] = _mean(hfr)
        d["agreement_with_checker"] = _mean(agree) if d["kind"] != CHECKER_KIND else None
        d["episodes_compared_with_checker"] = len(agree)
    used = sorted({j for s in scores for j in s.judges})
    return {
        "selection": selection.as_json(),
        "success": used,
        "success_rule": (
            "selected judges with verdicts on both branches of a pair; the pair's branch score is their mean"
        ),
        "hallucination": sorted({j for s in scores for j in s.hfr_judges}),
        "checker": sorted(j for j, d in per.items() if d["kind"] == CHECKER_KIND),
        "pairs_without_common_judge": sum(1 for s in scores if not s.judges),
        "per_judge": dict(sorted(per.items())),
    }
