"""Trial planning: real trials for a target half-width, with and without imagined runs."""

from __future__ import annotations

import math

import numpy as np
import pytest

from pilworld.ppi import pilot_agreement, plan_trials, real_trials_needed, smoothed_correlation

Z = 1.959963984540054


def test_classical_matches_the_closed_form() -> None:
    assert real_trials_needed(0.5, 0.9, 0.05, None) == math.ceil(Z * Z * 0.25 / 0.05**2) == 385
    assert real_trials_needed(0.3, 0.0, 0.1, 400) == math.ceil(Z * Z * 0.21 / 0.01)  # ρ = 0: imagined runs don't help
    assert real_trials_needed(0.5, 0.9, 0.05, 0) == 385


def test_the_limit_of_unlimited_imagined_runs() -> None:
    limit = real_trials_needed(0.5, 0.9, 0.05, math.inf)
    assert abs(limit - 385 * (1 - 0.81)) <= 1
    assert real_trials_needed(0.5, 1.0, 0.05, math.inf) == 2  # a perfect judge: the floor of two real trials


def test_the_answer_is_the_smallest_n_that_reaches_the_target() -> None:
    for p, rho, h, N in [(0.5, 0.9, 0.05, 400), (0.8, 0.7, 0.1, 100), (0.3, 0.5, 0.02, 4000)]:
        n = real_trials_needed(p, rho, h, N)

        def half(m: int, p: float = p, rho: float = rho, N: int = N) -> float:
            return Z * math.sqrt(p * (1 - p) / m * (1 - rho**2 * N / (N + m)))

        assert half(n) <= h < half(n - 1)


def test_extreme_pilot_rates_still_plan_real_trials() -> None:
    # p(1 − p) uses p clipped to [0.02, 0.98]: a 0/10 pilot does not mean the rate is known to be 0.
    assert real_trials_needed(0.0, 0.0, 0.05, None) == math.ceil(Z * Z * 0.02 * 0.98 / 0.05**2)
    assert real_trials_needed(1.0, 0.0, 0.05, None) == real_trials_needed(0.0, 0.0, 0.05, None)


def test_a_negative_correlation_saves_nothing() -> None:
    assert real_trials_needed(0.5, -0.9, 0.05, 1000) == 385  # the estimator clips λ at 0


def test_plan() -> None:
    plan = plan_trials(0.5, 0.9, 0.05)
    assert plan.classical == 385
    assert list(plan.with_imagined) == [50, 100, 200, 400, 1000, 4000]
    needed = list(plan.with_imagined.values())
    assert needed == sorted(needed, reverse=True) and needed[0] > needed[-1]
    assert plan.classical >= needed[0] and needed[-1] >= plan.limit
    saving = plan.classical - plan.limit
    worth = plan.imagined_worth
    assert worth >= 25 and math.log2(worth / 25).is_integer()  # on the doubling grid 25, 50, 100, …
    assert plan.classical - real_trials_needed(0.5, 0.9, 0.05, worth) >= 0.9 * saving
    assert plan.classical - real_trials_needed(0.5, 0.9, 0.05, worth // 2) < 0.9 * saving
    j = plan.to_json()
    assert j["with_imagined"]["400"] == plan.with_imagined[400]
    assert (j["classical"], j["limit"], j["imagined_worth"]) == (385, plan.limit, worth)


def test_no_saving_means_no_imagined_runs_worth_generating() -> None:
    assert plan_trials(0.5, 0.0, 0.05).imagined_worth == 0
    assert plan_trials(0.5, 0.05, 0.3).imagined_worth == 0  # saves less than one trial


def test_pilot_agreement() -> None:
    y = np.array([1, 1, 0, 1, 0, 1, 1, 0, 1, 1], dtype=float)
    f = y.copy()
    f[:2] = 1 - f[:2]
    p, rho = pilot_agreement(y, f)
    assert p == pytest.approx(0.7)
    assert rho == pytest.approx(smoothed_correlation(y, f))
    assert 0 < rho < float(np.corrcoef(y, f)[0, 1]) + 1e-12  # the pseudo-counts shrink it
    assert pilot_agreement(np.ones(5), np.ones(5))[1] > 0  # all agree, all succeed: smoothing keeps ρ defined
    assert pilot_agreement([1, 0], [1, 0])[0] == 0.5


@pytest.mark.parametrize(
    ("call", "message"),
    [
        (lambda: real_trials_needed(1.5, 0.5, 0.05, 100), r"p must be in \[0, 1\], got 1\.5"),
        (lambda: real_trials_needed(0.5, 1.2, 0.05, 100), r"rho must be in \[-1, 1\], got 1\.2"),
        (lambda: real_trials_needed(0.5, 0.5, 0.0, 100), r"half_width must be in \(0, 0\.5\], got 0\.0"),
        (lambda: real_trials_needed(0.5, 0.5, 0.6, 100), r"half_width must be in \(0, 0\.5\]"),
        (lambda: real_trials_needed(0.5, 0.5, 0.05, -1), r"N must be >= 0"),
        (lambda: real_trials_needed(0.5, 0.5, 0.05, 100, alpha=2), r"alpha must be in \(0, 1\)"),
        (lambda: plan_trials(0.5, 0.5, 0.05, grid=(0, 10)), r"grid must hold integers >= 1, got 0"),
        (lambda: pilot_agreement([], []), r"no paired subtasks \(n = 0\)"),
        (lambda: pilot_agreement([1, 0], [1]), r"y and f must have the same length"),
    ],
)
def test_errors(call: object, message: str) -> None:
    assert callable(call)
    with pytest.raises(ValueError, match=message):
        call()
