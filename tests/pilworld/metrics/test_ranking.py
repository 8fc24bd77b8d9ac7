"""Pearson, Spearman and MMRV on hand-computed vectors, including SimplerEnv's MMRV tie rule."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

from pilworld.metrics.ranking import average_ranks, mmrv, pearson, pearson_simplerenv, ranking_metrics, spearman


def test_pearson_of_a_hand_computed_vector() -> None:
    # x − x̄ = (−1, 0, 1), y − ȳ = (−7/3, −1/3, 8/3): Σ = 5, Σx² = 2, Σy² = 114/9 → r = 15 / √228.
    assert pearson([1, 2, 3], [2, 4, 7]) == pytest.approx(15 / math.sqrt(228), abs=1e-12)
    assert pearson([1, 2, 3], [3, 2, 1]) == pytest.approx(-1.0)
    assert pearson([0.2, 0.4], [0.1, 0.9]) == pytest.approx(1.0)  # two points always lie on a line


def test_pearson_of_a_constant_vector_is_none_with_a_reason() -> None:
    assert pearson([0.5, 0.5, 0.5], [0.1, 0.2, 0.3]) is None
    assert pearson([0.1, 0.2, 0.3], [1.0, 1.0, 1.0]) is None
    assert pearson([0.7, 0.7], [0.7, 0.7]) is None  # SimplerEnv would say 1 here; it is 0/0
    out = ranking_metrics([0.5, 0.5, 0.5], [0.1, 0.2, 0.3])
    assert out["pearson"] is None and out["spearman"] is None
    assert "SR_imag constant" in str(out["pearson_reason"])
    assert out["mmrv"] == pytest.approx((0 + 0.1 + 0.2) / 3)  # defined: ties in sim are violations (below)
    assert json.loads(json.dumps(out, allow_nan=False))["pearson"] is None


def test_fewer_than_two_settings_are_undefined() -> None:
    out = ranking_metrics([0.4], [0.6])
    assert out["pearson"] is None and out["spearman"] is None and out["mmrv"] is None
    assert "fewer than 2" in str(out["pearson_reason"]) and "fewer than 2" in str(out["mmrv_reason"])
    assert ranking_metrics([], [])["mmrv"] is None


def test_inputs_are_validated() -> None:
    with pytest.raises(ValueError, match="y: expected 3 values"):
        pearson([1, 2, 3], [1, 2])
    with pytest.raises(ValueError, match="finite"):
        mmrv([0.1, float("nan")], [0.1, 0.2])


def test_average_ranks_and_spearman_with_ties() -> None:
    np.testing.assert_array_equal(average_ranks([10, 20, 20, 30]), [1, 2.5, 2.5, 4])
    np.testing.assert_array_equal(average_ranks([3, 1, 3, 3]), [3, 1, 3, 3])
    # ranks x = (1, 2.5, 2.5, 4), y = (1, 3, 2, 4): centred (−1.5, 0, 0, 1.5), (−1.5, .5, −.5, 1.5)
    # → Σ = 4.5, Σx² = 4.5, Σy² = 5 → ρ = 4.5 / √22.5 = 3 / √10.
    assert spearman([1, 2, 2, 3], [1, 3, 2, 4]) == pytest.approx(3 / math.sqrt(10))
    assert spearman([0.1, 0.5, 0.9], [0.2, 0.3, 0.99]) == pytest.approx(1.0)  # monotone, not linear
    assert spearman([0.3, 0.3], [0.1, 0.2]) is None


def test_mmrv_of_orderings() -> None:
    assert mmrv([0.1, 0.5, 0.9], [0.2, 0.3, 0.8]) == 0.0  # same order
    # A full swap: each setting's worst violation is the real gap 0.8.
    assert mmrv([0.1, 0.9], [0.9, 0.1]) == pytest.approx(0.8)
    # One swapped pair (settings 1 and 2) in three: violations weigh |real_1 − real_2| = 0.1 for both.
    assert mmrv([0.1, 0.6, 0.5], [0.1, 0.4, 0.5]) == pytest.approx(2 * 0.1 / 3)


def test_mmrv_tie_rule_matches_simplerenv() -> None:
    # SimplerEnv: violation iff (sim_i > sim_j) != (real_i > real_j), weight |real_i − real_j|.
    # A tie in sim counts for the setting that is higher in real: i=1 vs j=0 → 0.2; mean over 2 = 0.1.
    # (A rule that ignored ties would give 0.)
    assert mmrv([0.5, 0.5], [0.2, 0.4]) == pytest.approx(0.1)
    # sim = (.5, .5, .9), real = (.2, .4, .1):
    #   i=0: j=2 (F vs T) → .1                       max .1
    #   i=1: j=0 (tie in sim, .4 > .2) → .2; j=2 → .3  max .3
    #   i=2: j=0 (T vs F) → .1; j=1 → .3              max .3   → MMRV = .7 / 3
    # With "<" instead of ">" the tie would be charged to i=0 (max .2) and MMRV would be .8 / 3.
    assert mmrv([0.5, 0.5, 0.9], [0.2, 0.4, 0.1]) == pytest.approx(0.7 / 3)
    # A tie in real costs nothing: the violation's weight |real_i − real_j| is 0.
    assert mmrv([0.2, 0.4], [0.5, 0.5]) == 0.0
    # Constant sim against spread real: every setting above the lowest real one is charged.
    assert mmrv([0.5, 0.5, 0.5], [0.1, 0.3, 0.3]) == pytest.approx((0 + 0.2 + 0.2) / 3)


def test_simplerenv_published_numbers() -> None:
    # SimplerEnv's REAL_PERF / SIMPLER_PERF for google_robot_pick_coke_can (simpler_env/utils/metrics.py,
    # policies rt-2-x, rt-1-converged, rt-1-15pct, rt-1-x, rt-1-begin, octo-base); their
    # mean_maximum_rank_violation gives 0.031333 and pearson_correlation 0.975434 (with its 1e-8 term).
    real = [0.907, 0.853, 0.920, 0.760, 0.133, 0.293]
    sim = [0.787, 0.857, 0.710, 0.567, 0.027, 0.170]
    assert mmrv(sim, real) == pytest.approx(0.031333333333, abs=1e-9)
    assert pearson(sim, real) == pytest.approx(0.975434, abs=1e-6)


def _denominator(x: list[float] | np.ndarray, y: list[float] | np.ndarray) -> float:
    dx, dy = np.asarray(x) - np.mean(x), np.asarray(y) - np.mean(y)
    return math.sqrt(float(np.sum(dx * dx)) * float(np.sum(dy * dy)))


def test_pearson_simplerenv_reproduces_its_published_value_and_special_cases() -> None:
    real = [0.907, 0.853, 0.920, 0.760, 0.133, 0.293]
    sim = [0.787, 0.857, 0.710, 0.567, 0.027, 0.170]
    assert pearson_simplerenv(sim, real) == pytest.approx(0.975434, abs=5e-7)
    assert pearson_simplerenv([0.7, 0.7], [0.7, 0.7]) == 1.0  # equal centred vectors, though r is 0/0
    assert pearson_simplerenv([0.5, 0.5, 0.5], [0.1, 0.2, 0.3]) == 0.0  # one constant vector
    assert abs(pearson_simplerenv([0.1, 0.1, 0.1], [0.1, 0.2, 0.3])) < 1e-20  # within float noise of 0
    assert pearson_simplerenv([0.2, 0.4, 0.9], [0.2, 0.4, 0.9]) == 1.0


def test_the_difference_from_simplerenv_is_exactly_the_documented_factor() -> None:
    # docs/metrics.md: SimplerEnv's r = ours · D / (D + 1e-8), so the gap is |r| · 1e-8 / (D + 1e-8).
    rng = np.random.default_rng(0)
    worst = {}
    for spread in (1.0, 0.05):
        gaps = []
        for _ in range(500):
            x, y = 0.5 + spread * (rng.random(15) - 0.5), 0.5 + spread * (rng.random(15) - 0.5)
            ours = pearson(x.tolist(), y.tolist())
            assert ours is not None
            d = _denominator(x, y)
            gap = ours - pearson_simplerenv(x.tolist(), y.tolist())
            assert gap == pytest.approx(ours * 1e-8 / (d + 1e-8), rel=1e-6, abs=1e-15)
            gaps.append(abs(gap))
        worst[spread] = max(gaps)
    assert worst[1.0] < 1e-7 < worst[0.05] < 1e-5  # the figures docs/metrics.md quotes
    close = pearson([0.74, 0.76], [0.72, 0.73])
    assert close == pytest.approx(1.0)
    assert close - pearson_simplerenv([0.74, 0.76], [0.72, 0.73]) == pytest.approx(1e-4, rel=1e-3)
