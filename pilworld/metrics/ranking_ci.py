"""Bootstrap intervals of the ranking metrics (Pearson, Spearman, MMRV across task × checkpoint settings).

One resampling redraws, within every setting, its pairs with replacement (a setting keeps its size,
so a setting never vanishes), recomputes each setting's SR_real and SR_imag from the drawn pairs, and
computes the three metrics across settings. A resampling where a metric is undefined (e.g. every
setting's SR_imag equal, so Pearson is 0/0) is left out of that metric's interval, and
``<metric>_defined`` says in how many resamplings it was defined — an interval over a few of 2,000
draws is reported, but says so.
"""

from __future__ import annotations

from collections import defaultdict
from collections.abc import Sequence
from typing import Any

import numpy as np

from pilworld.metrics.bootstrap import DEFAULT_RESAMPLES, DEFAULT_SEED, LEVEL, percentile_interval
from pilworld.metrics.ranking import mmrv, pearson, spearman
from pilworld.metrics.success import PairScore

METRICS = {"pearson": pearson, "spearman": spearman, "mmrv": mmrv}


def ranking_intervals(
    scores: Sequence[PairScore], *, resamples: int = DEFAULT_RESAMPLES, seed: int = DEFAULT_SEED, level: float = LEVEL
) -> dict[str, Any]:
    """``{metric: [lo, hi] | None, metric_defined: count}`` for Pearson, Spearman and MMRV (SR_imag vs SR_real)."""
    groups: dict[tuple[str, str], list[tuple[float, float]]] = defaultdict(list)
    for s in scores:
        if s.real is not None and s.imag is not None:
            groups[s.pair.setting].append((s.real, s.imag))
    out: dict[str, Any] = {"resamples": resamples, "seed": seed, "level": level, "n_settings": len(groups)}
    if len(groups) < 2 or resamples < 1:
        for name in METRICS:
            out[name] = None
            out[f"{name}_defined"] = 0
        out["reason"] = "fewer than 2 settings with both-branch verdicts" if len(groups) < 2 else "no resamples"
        return out
    rng = np.random.default_rng(seed)
    arrays = [np.asarray(v, dtype=np.float64) for _, v in sorted(groups.items())]
    samples: dict[str, list[float]] = {name: [] for name in METRICS}
    for _ in range(resamples):
        real, imag = [], []
        for a in arrays:
            drawn = a[rng.integers(0, len(a), size=len(a))]
            real.append(float(drawn[:, 0].mean()))
            imag.append(float(drawn[:, 1].mean()))
        for name, fn in METRICS.items():
            value = fn(imag, real)
            if value is not None:
                samples[name].append(value)
    for name in METRICS:
        values = np.asarray(samples[name], dtype=np.float64)
        out[name] = percentile_interval(values, level) if values.size else None
        out[f"{name}_defined"] = int(values.size)
    return out
