"""PPI++ intervals: wald reproduces ppi_py; wilson (the default) covers at the small n of real robot trials."""

from __future__ import annotations

import math
from statistics import NormalDist

import numpy as np

# ppi_py is a dev dependency and the reference for method="wald": a missing reference must fail, not skip.
import ppi_py
import pytest
from numpy.typing import NDArray

from pilworld.ppi import (
    Interval,
    PPIEstimate,
    classical_mean,
    difference,
    ess_gain_formula,
    normal_quantile,
    ppi_mean,
    ppi_mean_batch,
    smoothed_correlation,
    width_ratio_formula,
)

Array = NDArray[np.float64]


def _draw(
    rng: np.random.Generator, D: int, n: int, N: int, p: float, a: float, *, bias: float = 0.0
) -> tuple[Array, Array, Array]:
    """D problems: Y ~ Bernoulli(p); f = Y with probability a, else 1 − Y; then f = 1 with probability ``bias``.

    The unlabelled predictions come from fresh (Y, f) draws of the same distribution, as imagined-only
    subtasks of the same checkpoint would.
    """

    def predictions(y: Array) -> Array:
        f = np.where(rng.random(y.shape) < a, y, 1.0 - y)
        return np.where(rng.random(y.shape) < bias, 1.0, f)

    Y = (rng.random((D, n)) < p).astype(np.float64)
    U = predictions((rng.random((D, N)) < p).astype(np.float64))
    return Y, predictions(Y), U


def _coverage(r: dict[str, Array], p: float) -> float:
    return float(np.mean((r["lower"] <= p) & (p <= r["upper"])))


# ------------------------------------------------------------------------------------- wald = ppi_py


@pytest.mark.parametrize(("n", "N", "alpha"), [(2, 10, 0.05), (10, 100, 0.05), (20, 400, 0.1), (100, 30, 0.01)])
@pytest.mark.parametrize("kind", ["binary", "fractional"])
def test_wald_equals_ppi_py(n: int, N: int, alpha: float, kind: str) -> None:
    rng = np.random.default_rng(n * 1000 + N)
    for _ in range(5):
        if kind == "binary":
            Y, F, U = (a[0] for a in _draw(rng, 1, n, N, p=0.6, a=0.8))
        else:  # e.g. a mean over three judges, or a raw score
            Y, F, U = rng.random(n), np.clip(rng.random(n) * 0.5 + rng.random(n) * 0.5, 0, 1), rng.random(N)
            F = np.round(0.7 * Y + 0.3 * F, 3)
        e = ppi_mean(Y, F, U, alpha=alpha, method="wald")
        lo, hi = ppi_py.ppi_mean_ci(Y, F, U, alpha=alpha)
        c_lo, c_hi = ppi_py.classical_mean_ci(Y, alpha=alpha)
        assert e.ppi.lower == pytest.approx(float(lo[0]), abs=1e-10)
        assert e.ppi.upper == pytest.approx(float(hi[0]), abs=1e-10)
        assert e.ppi.estimate == pytest.approx(float(np.squeeze(ppi_py.ppi_mean_pointestimate(Y, F, U))), abs=1e-10)
        assert e.classical.lower == pytest.approx(float(c_lo), abs=1e-10)
        assert e.classical.upper == pytest.approx(float(c_hi), abs=1e-10)
        assert e.classical.estimate == pytest.approx(float(Y.mean()), abs=1e-12)
        fixed = ppi_mean(Y, F, U, alpha=alpha, method="wald", lam=0.3)
        lo, hi = ppi_py.ppi_mean_ci(Y, F, U, alpha=alpha, lam=0.3)
        assert (fixed.ppi.lower, fixed.ppi.upper) == pytest.approx((float(lo[0]), float(hi[0])), abs=1e-10)
        c = classical_mean(Y, alpha=alpha, method="wald")
        assert (c.lower, c.upper) == pytest.approx((float(c_lo), float(c_hi)), abs=1e-10)


def test_normal_quantile_matches_the_standard_library() -> None:
    for alpha in (0.5, 0.1, 0.05, 0.01, 1e-6):
        assert normal_quantile(alpha) == pytest.approx(NormalDist().inv_cdf(1 - alpha / 2), abs=1e-12)
    assert normal_quantile(0.05) == pytest.approx(1.959963984540054, abs=1e-12)


# ------------------------------------------------------------------------------------ batch = scalar


@pytest.mark.parametrize("method", ["wilson", "wald"])
def test_batch_equals_the_scalar_function_row_by_row(method: str) -> None:
    rng = np.random.default_rng(3)
    Y, F, U = _draw(rng, 40, 12, 90, p=0.7, a=0.8)
    F[0] = 1.0  # a constant predictor row
    r = ppi_mean_batch(Y, F, U, alpha=0.1, method=method, prior=0.2)
    assert set(r) >= {"estimate", "lower", "upper", "classical_estimate", "classical_lower", "classical_upper"}
    assert all(v.shape == (40,) for v in r.values())
    for i in range(40):
        e = ppi_mean(Y[i], F[i], U[i], alpha=0.1, method=method, prior=0.2)
        got = (e.ppi.estimate, e.ppi.lower, e.ppi.upper, e.classical.lower, e.classical.upper, e.lam, e.deff)
        want = tuple(float(r[k][i]) for k in ("estimate", "lower", "upper", "classical_lower", "classical_upper"))
        want += (float(r["lam"][i]), float(r["deff"][i]))
        assert got == pytest.approx(want, abs=1e-14)
        assert e.ess_gain == pytest.approx(1 / e.deff)


# ----------------------------------------------------------------------------------------- coverage


@pytest.mark.parametrize("a", [0.5, 0.9])
def test_wilson_covers_at_small_n(a: float) -> None:
    rng = np.random.default_rng(20240 + int(a * 10))
    hits = []
    for p in (0.2, 0.5, 0.8):
        r = ppi_mean_batch(*_draw(rng, 3000, 20, 400, p=p, a=a))
        hits.append(_coverage(r, p))
    pooled = float(np.mean(hits))
    print(f"wilson PPI coverage, n=20 N=400 a={a}: per p (0.2, 0.5, 0.8) {np.round(hits, 3)}, pooled {pooled:.3f}")
    assert 0.93 <= pooled <= 0.97


def test_wald_undercovers_at_small_n_which_is_why_wilson_is_the_default() -> None:
    rng = np.random.default_rng(11)
    draws = _draw(rng, 3000, 10, 100, p=0.9, a=0.9)
    wald, wilson = (_coverage(ppi_mean_batch(*draws, method=m), 0.9) for m in ("wald", "wilson"))
    print(f"n=10 N=100 p=0.9 a=0.9: wald coverage {wald:.3f}, wilson {wilson:.3f}")
    assert wald < 0.85
    assert wilson >= 0.93


def test_width_ratio_matches_the_formula() -> None:
    n, N, a, p = 40, 400, 0.9, 0.5
    rho = 2 * a - 1  # corr(Y, f) when f flips Y with probability 1 − a, at p = 0.5
    r = ppi_mean_batch(*_draw(np.random.default_rng(5), 3000, n, N, p=p, a=a))
    ratio = float(np.mean(r["upper"] - r["lower"]) / np.mean(r["classical_upper"] - r["classical_lower"]))
    formula = width_ratio_formula(rho, n, N)
    print(f"width ratio n=40 N=400 a=0.9: measured {ratio:.3f}, formula {formula:.3f}")
    assert ratio == pytest.approx(formula, rel=0.10)


@pytest.mark.parametrize("lam", [0.5, 1.0])
@pytest.mark.parametrize("method", ["wilson", "wald"])
def test_a_fixed_lambda_is_unbiased_even_with_a_biased_predictor(lam: float, method: str) -> None:
    p, D = 0.6, 4000
    draws = _draw(np.random.default_rng(8), D, 20, 200, p=p, a=0.8, bias=0.3)  # f says "success" 30 % extra
    est = ppi_mean_batch(*draws, method=method, lam=lam)["estimate"]
    se = float(est.std(ddof=1)) / math.sqrt(D)
    assert abs(float(est.mean()) - p) < 3 * se


@pytest.mark.parametrize("bias", [0.0, 0.3])
def test_the_tuned_lambda_leaves_a_small_bias_that_shrinks_with_n(bias: float) -> None:
    """λ̂ is estimated from the same pairs as mean(y − λ̂ f), so θ̂(λ̂) is unbiased only to O(1/n)."""
    p, D = 0.6, 20000
    rng = np.random.default_rng(8)
    biases = {}
    for n in (20, 80):
        est = ppi_mean_batch(*_draw(rng, D, n, 200, p=p, a=0.8, bias=bias))["estimate"]
        biases[n] = float(est.mean()) - p
        assert abs(biases[n]) < 0.1 * float(est.std())  # small beside the estimate's own spread
    print(f"tuned-λ bias (predictor bias {bias}): n=20 {biases[20]:+.4f}, n=80 {biases[80]:+.4f}")
    assert abs(biases[80]) < abs(biases[20]) / 2


# ----------------------------------------------------------------------------------------------- λ


def test_lambda_follows_the_predictor_quality() -> None:
    rng = np.random.default_rng(9)
    Y, _, U = _draw(rng, 2000, 20, 400, p=0.5, a=1.0)
    noise = (rng.random(Y.shape) < 0.5).astype(np.float64)
    assert float(np.mean(ppi_mean_batch(Y, noise, U)["lam"])) < 0.1  # independent f: close to classical
    perfect = ppi_mean_batch(Y, Y, U)["lam"]  # f == Y, N ≫ n: λ* = N/(N + n) ≈ 0.95, less the prior's shrinkage
    assert float(np.mean(perfect)) > 0.85
    # ppi_py divides a ddof-0 covariance by a ddof-1 variance: E[λ] ≈ N/(N + n)·(n − 1)/n.
    wald = ppi_mean_batch(Y, Y, U, method="wald")["lam"]
    assert float(np.mean(wald)) == pytest.approx(400 / 420 * 19 / 20, abs=0.02)


@pytest.mark.parametrize("method", ["wilson", "wald"])
def test_a_constant_predictor_gives_lambda_zero_and_the_classical_interval(method: str) -> None:
    y = np.array([1, 0, 1, 1, 0, 1, 1, 1, 0, 1], dtype=float)
    e = ppi_mean(y, np.ones(10), np.ones(50), method=method)
    assert e.lam == 0.0
    assert e.deff == 1.0
    assert (e.ppi.estimate, e.ppi.lower, e.ppi.upper) == pytest.approx(
        (e.classical.estimate, e.classical.lower, e.classical.upper), abs=1e-12
    )


def test_one_paired_subtask_works_for_wilson() -> None:
    e = ppi_mean([1], [1], [1, 1, 0, 1, 1, 1, 1, 0], method="wilson")
    assert 0.0 <= e.ppi.lower < e.ppi.upper <= 1.0
    assert math.isfinite(e.deff) and e.deff > 0
    assert e.rho is not None and 0 < e.rho < 1  # defined thanks to the pseudo-counts
    assert e.n == 1 and e.N == 8


def test_wilson_interval_is_inside_unit_range_and_classical_matches_the_textbook_formula() -> None:
    y = np.array([1.0] * 9 + [0.0])
    c = classical_mean(y)
    z, n, ph = 1.959963984540054, 10, 0.9
    centre = (ph + z * z / (2 * n)) / (1 + z * z / n)
    half = z * math.sqrt(ph * (1 - ph) / n + z * z / (4 * n * n)) / (1 + z * z / n)
    assert (c.lower, c.upper) == pytest.approx((centre - half, centre + half), abs=1e-12)
    all_ones = classical_mean(np.ones(10))
    assert all_ones.upper == 1.0 and all_ones.lower == pytest.approx(1 / (1 + z * z / 10), abs=1e-12)


def test_perfect_predictor_gain_and_rho() -> None:
    rng = np.random.default_rng(2)
    y = (rng.random(40) < 0.5).astype(float)
    u = (rng.random(4000) < 0.5).astype(float)
    e = ppi_mean(y, y, u)
    assert e.rho is not None and e.rho > 0.95
    assert e.ess_gain > 5  # the imagined runs stand in for most of the real ones
    assert e.ppi.half_width < e.classical.half_width / 2
    assert smoothed_correlation(y, y) == pytest.approx(e.rho)


# --------------------------------------------------------------------------------------- difference


def _row(r: dict[str, Array], i: int, n: int, N: int) -> PPIEstimate:
    ppi = Interval(float(r["estimate"][i]), float(r["lower"][i]), float(r["upper"][i]))
    classical = Interval(
        float(r["classical_estimate"][i]), float(r["classical_lower"][i]), float(r["classical_upper"][i])
    )
    lam, deff = float(r["lam"][i]), float(r["deff"][i])
    return PPIEstimate(ppi, classical, n, N, lam, None, deff, 1 / deff, "wilson", 0.05)


def test_difference_rarely_separates_equal_checkpoints_and_separates_distant_ones() -> None:
    rng = np.random.default_rng(4)
    D = 2000
    ra, rb = (ppi_mean_batch(*_draw(rng, D, 20, 200, p=0.6, a=0.8)) for _ in range(2))
    for which in ("ppi", "classical"):
        same = np.mean([difference(_row(ra, i, 20, 200), _row(rb, i, 20, 200), which).contains(0.0) for i in range(D)])
        print(f"difference ({which}) of equal checkpoints (n=20 N=200 a=0.8) contains 0 in {same:.3f} of draws")
        assert same >= 0.92
    lo, hi = (ppi_mean_batch(*_draw(rng, 200, 40, 200, p=p, a=0.8)) for p in (0.2, 0.8))
    for which in ("ppi", "classical"):
        assert all(difference(_row(hi, i, 40, 200), _row(lo, i, 40, 200), which).lower > 0 for i in range(200)), which
    # and the scalar path agrees with the rows it was built from
    Y, F, U = _draw(rng, 1, 20, 200, p=0.6, a=0.8)
    e = ppi_mean(Y[0], F[0], U[0])
    assert e.ppi == _row(ppi_mean_batch(Y, F, U), 0, 20, 200).ppi


def test_difference_formulas() -> None:
    def est(ppi: Interval, method: str) -> PPIEstimate:
        return PPIEstimate(ppi, ppi, 10, 100, 0.5, 0.8, 0.5, 2.0, method, 0.05)

    a, b = Interval(0.7, 0.5, 0.85), Interval(0.4, 0.2, 0.6)
    d = difference(est(a, "wilson"), est(b, "wilson"))
    assert d.estimate == pytest.approx(0.3)
    assert d.lower == pytest.approx(0.3 - math.hypot(0.2, 0.2))
    assert d.upper == pytest.approx(0.3 + math.hypot(0.15, 0.2))
    w = difference(est(a, "wald"), est(b, "wald"), "classical")
    assert (w.lower, w.upper) == pytest.approx((0.3 - math.hypot(0.175, 0.2), 0.3 + math.hypot(0.175, 0.2)))
    over = difference(est(Interval(1.02, 0.8, 1.0), "wilson"), est(b, "wilson"))
    assert over.estimate == pytest.approx(0.6)  # wilson clips the estimate so the interval holds it
    assert over.lower <= over.estimate <= over.upper


# ----------------------------------------------------------------------------------------- formulas


def test_formulas() -> None:
    assert width_ratio_formula(0.0, 10, 100) == 1.0
    assert width_ratio_formula(0.9, 40, 400) == pytest.approx(math.sqrt(1 - 0.81 * 400 / 440))
    assert ess_gain_formula(0.9, 40, 400) == pytest.approx(1 / (1 - 0.81 * 400 / 440))
    assert width_ratio_formula(0.8, 10, math.inf) == pytest.approx(0.6)
    assert ess_gain_formula(1.0, 10, math.inf) == math.inf
    assert width_ratio_formula(-0.9, 10, 100) == 1.0  # λ is clipped at 0: an anti-correlated judge is unused


def test_json() -> None:
    e = ppi_mean([1, 0, 1, 1], [1, 0, 1, 0], [1, 1, 0, 1, 0, 1])
    j = e.to_json()
    assert j["ppi"] == {"estimate": e.ppi.estimate, "lower": e.ppi.lower, "upper": e.ppi.upper}
    assert (j["n"], j["N"], j["method"], j["alpha"]) == (4, 6, "wilson", 0.05)
    assert e.ppi.half_width == pytest.approx((e.ppi.upper - e.ppi.lower) / 2)
    assert e.ppi.contains(e.ppi.lower) and not e.ppi.contains(e.ppi.upper + 1e-9)


# ------------------------------------------------------------------------------------------- errors


@pytest.mark.parametrize(
    ("call", "message"),
    [
        (lambda: ppi_mean([], [], [1, 0]), r"^no paired subtasks \(n = 0\): PPI needs at least one real outcome$"),
        (lambda: ppi_mean([1], [1], []), r"no imagined-only subtasks \(N = 0\).*use classical_mean"),
        (lambda: ppi_mean([1, 0], [1], [1]), r"y and f must have the same length .* got 2 and 1"),
        (lambda: ppi_mean([1, 2], [1, 0], [1]), r"y must hold values in \[0, 1\].*found 2\.0"),
        (lambda: ppi_mean([1, 0], [1, np.nan], [1]), r"f must hold values in \[0, 1\] with no NaN"),
        (lambda: ppi_mean([1, 0], [1, 0], [-0.1]), r"f_unlabeled must hold values in \[0, 1\]"),
        (lambda: ppi_mean([1], [1], [1], alpha=1.0), r"alpha must be in \(0, 1\), got 1\.0"),
        (lambda: ppi_mean([1], [1], [1], alpha=0), r"alpha must be in \(0, 1\), got 0"),
        (lambda: ppi_mean([1], [1], [1], method="bootstrap"), r"unknown method 'bootstrap'"),
        (lambda: ppi_mean([1], [1], [1], prior=-0.1), r"prior must be a finite pseudo-count >= 0, got -0\.1"),
        (lambda: ppi_mean([1], [1], [1], method="wald"), r"wald needs n ≥ 2"),
        (lambda: classical_mean([]), r"no real outcomes \(n = 0\)"),
        (lambda: classical_mean([1], method="wald"), r"wald needs n ≥ 2"),
        (lambda: ppi_mean_batch(np.ones((2, 3)), np.ones((2, 4)), np.ones((2, 5))), r"Y and F must have the same"),
        (lambda: ppi_mean_batch(np.ones((2, 3)), np.ones((2, 3)), np.ones((3, 5))), r"U must have as many rows"),
        (lambda: ppi_mean_batch(np.ones(3), np.ones(3), np.ones(5)), r"Y must be 2-D"),
        (lambda: ppi_mean([1], [1], [1], lam=1.5), r"lam must be in \[0, 1\] or None"),
        (lambda: width_ratio_formula(1.5, 10, 10), r"rho must be in \[-1, 1\]"),
    ],
)
def test_errors(call: object, message: str) -> None:
    assert callable(call)
    with pytest.raises(ValueError, match=message):
        call()


def test_difference_errors() -> None:
    y = [1, 0, 1, 1]
    wilson, wald = ppi_mean(y, y, [1, 0]), ppi_mean(y, y, [1, 0], method="wald")
    with pytest.raises(ValueError, match="one method"):
        difference(wilson, wald)
    with pytest.raises(ValueError, match="one alpha"):
        difference(wilson, ppi_mean(y, y, [1, 0], alpha=0.1))
    with pytest.raises(ValueError, match="which must be 'ppi' or 'classical'"):
        difference(wilson, wilson, "real")
