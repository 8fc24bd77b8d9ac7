"""Bootstrap intervals over pairs: seeded, paired across metrics, containing the point estimate."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from pilworld.data.outcomes import Outcome
from pilworld.data.pairs import Pair, PairedEpisodes
from pilworld.metrics.bootstrap import bootstrap_means, percentile_interval
from pilworld.metrics.success import group_metrics, score_pairs


def _random_run(n: int, seed: int = 1) -> PairedEpisodes:
    rng = np.random.default_rng(seed)
    pairs = [Pair(f"t/c/seed0/subtask{i}", "t", "c", imagined=2 * i, real=2 * i + 1) for i in range(n)]
    verdicts: dict[int, list[Outcome]] = {}
    for i in range(n):
        for judge in ("A", "B", "C"):
            t_h = int(rng.integers(1, 16)) if rng.random() < 0.5 else None
            verdicts.setdefault(2 * i, []).append(Outcome(2 * i, judge, "human", bool(rng.random() < 0.4), 16, t_h))
            verdicts.setdefault(2 * i + 1, []).append(Outcome(2 * i + 1, judge, "human", bool(rng.random() < 0.7), 16))
    return PairedEpisodes(root=Path(), pairs=pairs, verdicts=verdicts)


def test_intervals_contain_the_estimate_and_repeat_with_the_seed() -> None:
    scores = score_pairs(_random_run(30))
    m = group_metrics(scores, bootstrap=2000, seed=0)
    for key in ("sr_real", "sr_imag", "hfr", "delta_sr", "abs_delta_sr"):
        lo, hi = m["ci95"][key]
        assert lo <= m[key] <= hi, key
        assert hi - lo > 0.05, key  # 30 noisy pairs: a real spread, not a degenerate interval
    assert group_metrics(scores, bootstrap=2000, seed=0)["ci95"] == m["ci95"]
    assert group_metrics(scores, bootstrap=2000, seed=1)["ci95"] != m["ci95"]


def test_one_pair_gives_a_point_interval_and_missing_values_are_skipped() -> None:
    ci = bootstrap_means({"a": np.array([0.25]), "b": np.array([np.nan])}, resamples=50, seed=0)
    assert ci == {"a": [0.25, 0.25], "b": None}
    # Resamples that drew only pairs without a value leave that metric's interval.
    ci = bootstrap_means({"a": np.array([1.0, np.nan])}, resamples=200, seed=0)
    assert ci["a"] == [1.0, 1.0]


def test_differences_are_paired() -> None:
    # imag = real + 0.1 on every pair: every resampling has the same difference.
    real = np.linspace(0, 0.8, 9)
    ci = bootstrap_means({"r": real, "i": real + 0.1}, differences={"d": ("i", "r")}, resamples=300, seed=3)
    assert ci["d"] == pytest.approx([0.1, 0.1]) and ci["abs_d"] == pytest.approx([0.1, 0.1])


def test_percentile_interval_and_bad_input() -> None:
    assert percentile_interval(np.arange(101, dtype=np.float64)) == pytest.approx([2.5, 97.5])
    assert percentile_interval(np.array([np.nan])) is None
    with pytest.raises(ValueError, match="resamples"):
        bootstrap_means({"a": np.ones(3)}, resamples=0)
    with pytest.raises(ValueError, match="equal lengths"):
        bootstrap_means({"a": np.ones(3), "b": np.ones(2)})
