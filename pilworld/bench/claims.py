"""Per-pair agreement and the paper's claims, compared between world-model variants on the same pairs.

Every variant of ``pilworld bench paired`` runs the same pairs with the same (copied) real branches, so two
variants differ only in their imagined branches. That makes a **paired** comparison possible: resample the
pairs once, and compute both variants' figures on the same drawn pairs. The difference's 95 % percentile
interval then says whether one variant is better on these pairs or whether the two cannot be told apart
— much tighter than comparing two unpaired intervals.

* :func:`agreement` — of the real successes, the share also imagined a success (and of the real failures,
  the share also imagined a failure), overall and per task, with Wilson 95 % intervals.
* :func:`compare` — variant ``a`` minus variant ``b`` on |ΔSR|, HFR and per-pair agreement (the share of
  pairs whose imagined verdict equals the real one), with paired bootstrap intervals.
* :data:`PAPER_CLAIMS` and :func:`paper_claims` — the paper's directions (the control video beats raw-action
  tokens, history memory matters, failure data matters), each a :func:`compare` and a verdict: ``holds``
  (the interval excludes zero on the claimed side), ``not separated`` (it includes zero) or ``reversed``.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from itertools import pairwise
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from pilworld.metrics.bootstrap import DEFAULT_RESAMPLES, DEFAULT_SEED, percentile_interval, resample_indices

Z95 = 1.959963984540054


def wilson(successes: int, n: int, z: float = Z95) -> list[float] | None:
    """The Wilson score interval of a proportion (None for n = 0); good at 0/n and n/n, unlike the Wald one."""
    if n <= 0:
        return None
    p = successes / n
    denom = 1.0 + z * z / n
    centre = (p + z * z / (2 * n)) / denom
    half = z * math.sqrt(p * (1 - p) / n + z * z / (4 * n * n)) / denom
    # At 0/n and n/n the bound is exactly 0 or 1 (the formula gives it up to rounding).
    return [0.0 if successes == 0 else max(0.0, centre - half), 1.0 if successes == n else min(1.0, centre + half)]


@dataclass(frozen=True)
class Verdicts:
    """One variant's judged pairs: pair id → (task, real success, imagined success, imagined HFR)."""

    pairs: dict[str, tuple[str, float, float, float]]

    @classmethod
    def load(cls, run: str | Path) -> Verdicts:
        from pilworld.data.judge_selection import read_selection
        from pilworld.data.pairs import load_pairs
        from pilworld.metrics.success import score_pairs

        out = {}
        for s in score_pairs(load_pairs(run), read_selection(run)):
            if s.real is None or s.imag is None:
                continue  # no judge gave verdicts on both branches: not counted, as in the metrics
            hfr = math.nan if s.hfr is None else float(s.hfr)
            out[s.pair.pair_id] = (s.pair.task, float(s.real), float(s.imag), hfr)
        return cls(out)


def _share(hits: int, n: int) -> dict[str, Any]:
    return {"k": hits, "n": n, "share": hits / n if n else None, "ci95": wilson(hits, n)}


def agreement(verdicts: Verdicts) -> dict[str, Any]:
    """Per-pair agreement of the imagined verdict with the real one, overall and per task (Wilson intervals).

    ``successes``: of the pairs whose real branch succeeded, how many also succeeded imagined;
    ``failures``: of the real failures, how many also failed imagined (a model that "repairs" failures, as
    video priors do, scores low here); ``all``: pairs whose two verdicts agree.
    """

    def block(rows: Sequence[tuple[str, float, float, float]]) -> dict[str, Any]:
        wins = [i for _, r, i, _ in rows if r >= 0.5]
        fails = [i for _, r, i, _ in rows if r < 0.5]
        same = sum(1 for _, r, i, _ in rows if (r >= 0.5) == (i >= 0.5))
        return {
            "successes": _share(sum(1 for i in wins if i >= 0.5), len(wins)),
            "failures": _share(sum(1 for i in fails if i < 0.5), len(fails)),
            "all": _share(same, len(rows)),
        }

    rows = list(verdicts.pairs.values())
    tasks = sorted({t for t, *_ in rows})
    return {**block(rows), "tasks": {t: block([r for r in rows if r[0] == t]) for t in tasks}}


def _columns(a: Verdicts, b: Verdicts) -> tuple[list[str], dict[str, NDArray[np.float64]]]:
    """The pairs both variants judged, and their per-pair columns (in one order)."""
    ids = sorted(set(a.pairs) & set(b.pairs))
    if not ids:
        raise ValueError("compare: the two variants have no judged pair in common")
    real_a = np.array([a.pairs[i][1] for i in ids])
    real_b = np.array([b.pairs[i][1] for i in ids])
    if not np.array_equal(real_a >= 0.5, real_b >= 0.5):
        # Shared real branches give identical real verdicts; anything else is not a paired comparison.
        raise ValueError("compare: the variants' real verdicts differ on the same pairs (real branches not shared)")
    cols = {
        "real": real_a,
        "imag_a": np.array([a.pairs[i][2] for i in ids]),
        "imag_b": np.array([b.pairs[i][2] for i in ids]),
        "hfr_a": np.array([a.pairs[i][3] for i in ids]),
        "hfr_b": np.array([b.pairs[i][3] for i in ids]),
    }
    cols["agree_a"] = ((cols["imag_a"] >= 0.5) == (cols["real"] >= 0.5)).astype(np.float64)
    cols["agree_b"] = ((cols["imag_b"] >= 0.5) == (cols["real"] >= 0.5)).astype(np.float64)
    return ids, cols


def _figures(cols: Mapping[str, NDArray[np.float64]], idx: NDArray[np.int64]) -> dict[str, NDArray[np.float64]]:
    """a − b of each figure on every resampling (rows of ``idx``); lower |ΔSR| is better, higher HFR and
    agreement are better."""

    def mean(name: str) -> NDArray[np.float64]:
        drawn = cols[name][idx]
        ok = np.isfinite(drawn)
        with np.errstate(invalid="ignore", divide="ignore"):
            out: NDArray[np.float64] = np.where(ok, drawn, 0.0).sum(axis=1) / ok.sum(axis=1)
        return out

    real = mean("real")
    return {
        "abs_delta_sr": np.abs(mean("imag_a") - real) - np.abs(mean("imag_b") - real),
        "hfr": mean("hfr_a") - mean("hfr_b"),
        "agreement": mean("agree_a") - mean("agree_b"),
    }


def compare(
    a: Verdicts, b: Verdicts, *, resamples: int = DEFAULT_RESAMPLES, seed: int = DEFAULT_SEED
) -> dict[str, Any]:
    """``a`` − ``b`` on |ΔSR|, HFR and per-pair agreement, with paired bootstrap 95 % intervals."""
    ids, cols = _columns(a, b)
    point = {k: float(v[0]) for k, v in _figures(cols, np.arange(len(ids))[None]).items()}
    draws: dict[str, list[NDArray[np.float64]]] = {k: [] for k in point}
    for idx in resample_indices(len(ids), resamples, seed):
        for k, v in _figures(cols, idx).items():
            draws[k].append(v)
    return {
        "pairs": len(ids),
        "difference": point,
        "ci95": {k: percentile_interval(np.concatenate(v)) for k, v in draws.items()},
    }


# (name, better, worse, what the paper claims). ``better`` is the variant the paper says is more accurate.
PAPER_CLAIMS: tuple[tuple[str, str, str, str], ...] = (
    (
        "control_video_vs_tokens",
        "v2_paper_gamma",
        "v2_ctrl_world",
        "the paper's control video Γ beats Ctrl-World-style per-frame action tokens (paper Table 1)",
    ),
    (
        "gamma_plus_vs_tokens",
        "pilworld",
        "v2_ctrl_world",
        "our control video Γ⁺ beats per-frame action tokens",
    ),
    ("history", "pilworld", "v2_no_history", "the history memory matters (paper ablation)"),
    ("failure_data", "pilworld", "v2_success_only", "failure data in training matters (paper ablation)"),
)
# The figure a claim is decided on, and which sign of (better − worse) is an improvement.
DECIDING = {"abs_delta_sr": -1.0, "hfr": 1.0, "agreement": 1.0}


def direction(diff: float, ci: Sequence[float] | None, sign: float) -> str:
    """``holds`` if the interval of (better − worse) lies on the improving side of zero, ``reversed`` if on
    the other, else ``not separated`` (the pairs cannot tell the two apart)."""
    if ci is None:
        return "undefined"
    lo, hi = sorted((sign * ci[0], sign * ci[1]))
    if lo > 0:
        return "holds"
    if hi < 0:
        return "reversed"
    return "not separated"


def paper_claims(verdicts: Mapping[str, Verdicts], **kwargs: Any) -> list[dict[str, Any]]:
    """Each claim of :data:`PAPER_CLAIMS` whose two variants were run: the paired comparison and, per figure,
    whether the paper's direction holds on these pairs."""
    out = []
    for name, better, worse, claim in PAPER_CLAIMS:
        if better not in verdicts or worse not in verdicts:
            continue
        c = compare(verdicts[better], verdicts[worse], **kwargs)
        c["direction"] = {k: direction(c["difference"][k], c["ci95"][k], s) for k, s in DECIDING.items()}
        out.append({"claim": name, "better": better, "worse": worse, "text": claim, **c})
    return out


def steps(verdicts: Mapping[str, Verdicts], names: Sequence[str], **kwargs: Any) -> list[dict[str, Any]]:
    """Each row of a ladder against the row before it (``to`` − ``from``, paired on the same pairs), with the
    direction of the step: ``holds`` where the later row is better. The Γ⁺ ablation reads as such a ladder,
    from the paper's markers to the shipped render + prior + paste."""
    present = [n for n in names if n in verdicts]
    out = []
    for prev, nxt in pairwise(present):
        c = compare(verdicts[nxt], verdicts[prev], **kwargs)
        c["direction"] = {k: direction(c["difference"][k], c["ci95"][k], s) for k, s in DECIDING.items()}
        out.append({"from": prev, "to": nxt, **c})
    return out
