"""Percentile bootstrap over subtasks (pairs): resample pairs with replacement, recompute, take 2.5 / 97.5 %.

One resampling draws ``n`` pair indices with replacement from the ``n`` pairs of a group (a task, or
all pairs); every metric of that resampling is computed from the same drawn pairs, so SR_real, SR_imag
and their difference stay paired. A per-pair value may be missing (NaN: e.g. no hallucination verdict
on that pair); a metric's mean then runs over the drawn pairs that have it, and a resampling that drew
none of them is left out of that metric's interval. The generator is ``numpy.random.default_rng(seed)``,
created afresh for each group, so a task's interval does not depend on which other tasks the run holds.
"""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np
from numpy.typing import NDArray

DEFAULT_RESAMPLES = 2000
DEFAULT_SEED = 0
LEVEL = 0.95
_BLOCK = 256  # resamplings drawn at once: bounds memory at _BLOCK × n floats per metric


def resample_indices(n: int, resamples: int, seed: int) -> list[NDArray[np.int64]]:
    """Blocks of drawn pair indices, shapes (≤ _BLOCK, n), ``resamples`` rows in all."""
    if isinstance(resamples, bool) or not isinstance(resamples, int) or resamples < 1:
        raise ValueError(f"bootstrap: expected an integer number of resamples >= 1, got {resamples!r}")
    if n < 1:
        raise ValueError("bootstrap: needs at least one pair")
    rng = np.random.default_rng(seed)
    blocks = []
    for start in range(0, resamples, _BLOCK):
        rows = min(_BLOCK, resamples - start)
        blocks.append(rng.integers(0, n, size=(rows, n), dtype=np.int64))
    return blocks


def nan_means(values: NDArray[np.float64], idx: NDArray[np.int64]) -> NDArray[np.float64]:
    """Mean of ``values[idx]`` along each row, ignoring NaN; NaN for a row with no finite value."""
    drawn = values[idx]  # (rows, n)
    ok = np.isfinite(drawn)
    counts = ok.sum(axis=1)
    sums = np.where(ok, drawn, 0.0).sum(axis=1)
    out = np.full(drawn.shape[0], np.nan)
    np.divide(sums, counts, out=out, where=counts > 0)
    return out


def percentile_interval(samples: NDArray[np.float64], level: float = LEVEL) -> list[float] | None:
    """The central ``level`` percentile interval of the finite samples, or None if there are none."""
    s = samples[np.isfinite(samples)]
    if s.size == 0:
        return None
    tail = (1.0 - level) / 2 * 100
    lo, hi = np.percentile(s, [tail, 100 - tail])
    return [float(lo), float(hi)]


def bootstrap_means(
    columns: Mapping[str, NDArray[np.float64]],
    *,
    differences: Mapping[str, tuple[str, str]] | None = None,
    resamples: int = DEFAULT_RESAMPLES,
    seed: int = DEFAULT_SEED,
) -> dict[str, list[float] | None]:
    """95 % percentile intervals of the NaN-aware mean of every column, over pairs resampled together.

    ``columns`` maps a name to per-pair values (one row per pair, NaN = missing, all the same length).
    ``differences`` adds ``name → (a, b)``: the interval of mean(a) − mean(b), and of its absolute
    value as ``abs_<name>``.
    """
    lengths = {k: np.asarray(v).shape for k, v in columns.items()}
    if len(set(lengths.values())) != 1:
        raise ValueError(f"columns: expected equal lengths, got {lengths}")
    n = next(iter(lengths.values()))[0]
    draws: dict[str, list[NDArray[np.float64]]] = {k: [] for k in columns}
    for idx in resample_indices(n, resamples, seed):
        for name, values in columns.items():
            draws[name].append(nan_means(np.asarray(values, dtype=np.float64), idx))
    means = {k: np.concatenate(v) for k, v in draws.items()}
    out = {k: percentile_interval(v) for k, v in means.items()}
    for name, (a, b) in (differences or {}).items():
        diff = means[a] - means[b]
        out[name] = percentile_interval(diff)
        out[f"abs_{name}"] = percentile_interval(np.abs(diff))
    return out
