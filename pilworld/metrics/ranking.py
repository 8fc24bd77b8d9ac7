"""Agreement of imagined and real success rates across settings: Pearson, Spearman and MMRV.

The definitions follow SimplerEnv (Li et al. 2024), ``simpler_env/utils/metrics.py`` in
github.com/simpler-env/SimplerEnv (``pearson_correlation``, ``mean_maximum_rank_violation``), applied
here with "sim" = the imagined branch's success rates and "real" = the real branch's, one value per
task × checkpoint setting. Our code is written from those definitions, not copied.

Where we differ from that file, on purpose (both differences are exact, not approximate):

* **Pearson** is the exact coefficient. SimplerEnv's ``pearson_correlation`` divides by
  ``D + 1e-8`` with ``D = √(Σ(x−x̄)² Σ(y−ȳ)²)``, so its value is ours times ``D / (D + 1e-8)``; the
  difference ``|r| · 1e-8 / (D + 1e-8)`` is not bounded by a fixed figure but grows as the success
  rates bunch together: for 15 settings spread over [0, 1] it stays near 1e-8, over a band 0.05 wide
  it reaches 5e-6, and for two settings 0.01 apart 1e-4. The guard only stops a division by zero,
  and it biases r towards 0 exactly where settings are hard to tell apart, so we keep the
  coefficient exact and handle 0/0 explicitly instead.
* **Constant vectors**: when either vector is constant, r is 0/0, undefined, and we return ``None``
  (with a reason). SimplerEnv returns 1 when both centred vectors are equal element-wise (two constant
  vectors included) and 0, or a value within float noise of 0, when only one is constant.
* Every function returns ``None`` for fewer than two settings, where no ranking exists.

:func:`pearson_simplerenv` reproduces SimplerEnv's formula exactly (tested against its published
numbers) for comparing with figures computed that way; the metrics report only :func:`pearson`.

MMRV is replicated exactly, tie rule included (see :func:`mmrv`).
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np
from numpy.typing import NDArray

MIN_SETTINGS = 2


def _vectors(x: Sequence[float], y: Sequence[float]) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    a = np.asarray(x, dtype=np.float64)
    b = np.asarray(y, dtype=np.float64)
    if a.ndim != 1 or b.ndim != 1:
        raise ValueError(f"x, y: expected 1-D sequences, got shapes {a.shape} and {b.shape}")
    if a.shape != b.shape:
        raise ValueError(f"y: expected {a.shape[0]} values like x, got {b.shape[0]}")
    if not (np.all(np.isfinite(a)) and np.all(np.isfinite(b))):
        raise ValueError("x, y: values must be finite")
    return a, b


def _constant(a: NDArray[np.float64]) -> bool:
    # Success rates are means of 0/1 verdicts; a spread below 1e-12 is float noise, not a ranking.
    return bool(np.ptp(a) <= 1e-12)


def undefined_reason(x: Sequence[float], y: Sequence[float], *, names: tuple[str, str] = ("x", "y")) -> str | None:
    """Why a correlation of ``x`` and ``y`` is undefined (fewer than 2 values, a constant vector), else None."""
    a, b = _vectors(x, y)
    if a.shape[0] < MIN_SETTINGS:
        return f"fewer than {MIN_SETTINGS} settings ({a.shape[0]})"
    constant = [n for n, v in zip(names, (a, b), strict=True) if _constant(v)]
    if constant:
        return f"{' and '.join(constant)} constant across settings (correlation is 0/0)"
    return None


def pearson(x: Sequence[float], y: Sequence[float]) -> float | None:
    """Pearson's r = Σ(x−x̄)(y−ȳ) / √(Σ(x−x̄)² Σ(y−ȳ)²); ``None`` if undefined (see :func:`undefined_reason`)."""
    a, b = _vectors(x, y)
    if undefined_reason(a.tolist(), b.tolist()) is not None:
        return None
    da, db = a - a.mean(), b - b.mean()
    r = float(np.sum(da * db) / math.sqrt(float(np.sum(da * da)) * float(np.sum(db * db))))
    return min(1.0, max(-1.0, r))  # rounding can overshoot ±1 by an ulp


def pearson_simplerenv(x: Sequence[float], y: Sequence[float]) -> float:
    """SimplerEnv's ``pearson_correlation``, written from its definition: 1 when the centred vectors are
    equal element-wise, else Σ(x−x̄)(y−ȳ) / (√(Σ(x−x̄)² Σ(y−ȳ)²) + 1e-8). Always a number (no 0/0)."""
    a, b = _vectors(x, y)
    da, db = a - a.mean(), b - b.mean()
    if np.all(da == db):
        return 1.0
    return float(np.sum(da * db) / (math.sqrt(float(np.sum(da * da)) * float(np.sum(db * db))) + 1e-8))


def average_ranks(x: Sequence[float]) -> NDArray[np.float64]:
    """1-based ranks, ties sharing the mean of the ranks they span ([10, 20, 20, 30] → [1, 2.5, 2.5, 4])."""
    a = np.asarray(x, dtype=np.float64)
    order = np.argsort(a, kind="stable")
    ranks = np.empty(a.shape[0], dtype=np.float64)
    i = 0
    while i < a.shape[0]:
        j = i
        while j + 1 < a.shape[0] and a[order[j + 1]] == a[order[i]]:
            j += 1
        ranks[order[i : j + 1]] = (i + j) / 2 + 1  # positions i..j hold ranks i+1..j+1
        i = j + 1
    return ranks


def spearman(x: Sequence[float], y: Sequence[float]) -> float | None:
    """Spearman's ρ: Pearson's r of the average ranks; ``None`` if undefined (all values of x or y tied)."""
    a, b = _vectors(x, y)
    return pearson(average_ranks(a.tolist()).tolist(), average_ranks(b.tolist()).tolist())


def mmrv(sim: Sequence[float], real: Sequence[float]) -> float | None:
    """Mean maximum rank violation of ``sim`` against ``real`` (SimplerEnv's definition), lower is better.

    MMRV = (1/N) Σ_i max_j 1[(sim_i > sim_j) ≠ (real_i > real_j)] · |real_i − real_j|   (max of nothing = 0)

    The violation is weighted by the gap in the *real* success rates. Tie rule (as SimplerEnv's strict
    ``>``): a tie in ``sim`` where ``real_i > real_j`` counts as a violation for i (not for j), weighted
    by the real gap, so a simulator that cannot separate two settings the real world separates is
    penalised; a tie in ``real`` counts as a violation of weight |real_i − real_j| = 0, so it costs
    nothing. ``None`` for fewer than two settings; constant vectors are fine.
    """
    s, r = _vectors(sim, real)
    n = s.shape[0]
    if n < MIN_SETTINGS:
        return None
    worst = np.zeros(n, dtype=np.float64)
    for i in range(n):
        for j in range(n):
            if (s[i] > s[j]) != (r[i] > r[j]):
                worst[i] = max(worst[i], abs(r[i] - r[j]))
    return float(worst.mean())


def ranking_metrics(sim: Sequence[float], real: Sequence[float]) -> dict[str, float | str | None]:
    """``{pearson, spearman, mmrv}`` of imagined (``sim``) vs real rates, with ``*_reason`` for each ``None``."""
    out: dict[str, float | str | None] = {
        "pearson": pearson(sim, real),
        "spearman": spearman(sim, real),
        "mmrv": mmrv(sim, real),
    }
    names = ("SR_imag", "SR_real")
    if out["pearson"] is None:
        out["pearson_reason"] = undefined_reason(sim, real, names=names)
    if out["spearman"] is None:  # the ranks are constant exactly when the values are all tied
        out["spearman_reason"] = undefined_reason(sim, real, names=names)
    if out["mmrv"] is None:
        out["mmrv_reason"] = f"fewer than {MIN_SETTINGS} settings ({len(sim)})"
    return out
