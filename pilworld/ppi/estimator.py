"""Prediction-powered intervals of a success rate (PPI++ with power tuning; Angelopoulos et al., arXiv:2311.01453).

A checkpoint is run on ``n`` paired subtasks, each with a real outcome ``y`` and an imagined outcome ``f``
(the world model's verdict on the same subtask), and on ``N`` more subtasks in the world model only
(``f_unlabeled``). The PPI++ estimate of the real success rate,

    θ̂(λ) = λ·mean(f_unlabeled) + mean(y − λ·f),

is unbiased for any fixed λ; λ is tuned to minimise its plug-in variance

    V(λ) = Var(y − λ f)/n + λ²·Var(f_unlabeled)/N,   λ* = Cov(y, f) / ((1 + n/N)·Var(f)),  clipped to [0, 1].

Two interval methods:

* ``"wald"`` reproduces ``ppi_py.ppi_mean_ci`` / ``ppi_py.classical_mean_ci`` exactly (normal interval
  around θ̂). It is the textbook interval, but for binary outcomes at n ≤ 20 it undercovers badly (at
  n = 10, p = 0.9 it covers ~60 %): the plug-in variance is often 0 or tiny.
* ``"wilson"`` (the default) turns the PPI variance into an effective sample size n_eff = n·V_classical/V_ppi
  and takes a Wilson score interval at n_eff around θ̂. The variances come from the labelled 2×2 table of
  (y, f) smoothed by a weak Dirichlet prior, so they are never 0 and n = 1 is defined; the point estimate
  itself stays the unsmoothed PPI++ one (unbiased for a fixed λ; with λ tuned on the same pairs its bias
  is of order 1/n, measured at +0.002 for n = 20 in the tests).

The core (``ppi_mean_batch``) is vectorised over a leading batch axis because the benchmark evaluates
~10⁶ intervals; ``ppi_mean`` is a batch of one. Only numpy and the standard library are used: ppi_py
(which pulls in scipy, statsmodels, sklearn, numba) is a test-time reference, not a dependency.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from statistics import NormalDist
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

METHODS = ("wilson", "wald")
DEFAULT_ALPHA = 0.05
DEFAULT_PRIOR = 0.1  # pseudo-count per cell of the 2×2 (y, f) table: 0.4 pseudo-pairs in all

Array = NDArray[np.float64]


@dataclass(frozen=True)
class Interval:
    """A point estimate and a two-sided interval.

    For a PPI interval ``estimate`` is the unbiased PPI++ estimate, which can stray slightly outside
    [0, 1] (it is a difference of means); the Wilson bounds are clipped to [0, 1], the Wald ones are
    not (they equal ppi_py's).
    """

    estimate: float
    lower: float
    upper: float

    @property
    def half_width(self) -> float:
        return (self.upper - self.lower) / 2

    def contains(self, value: float) -> bool:
        return self.lower <= value <= self.upper

    def to_json(self) -> dict[str, float]:
        return {"estimate": self.estimate, "lower": self.lower, "upper": self.upper}


@dataclass(frozen=True)
class PPIEstimate:
    """The prediction-powered interval of one success rate, with the classical one it improves on.

    ``ess_gain`` = 1/``deff``: how many labelled real trials each real trial is worth once the imagined
    runs are used (2.0: the PPI interval is as narrow as a classical one from twice the real trials).
    """

    ppi: Interval
    classical: Interval  # from the n labelled real outcomes alone, same method
    n: int
    N: int
    lam: float
    rho: float | None  # correlation of y and f (smoothed table for wilson); None where undefined
    deff: float  # V_ppi / V_classical
    ess_gain: float
    method: str
    alpha: float

    def to_json(self) -> dict[str, Any]:
        return {
            "ppi": self.ppi.to_json(),
            "classical": self.classical.to_json(),
            "n": self.n,
            "N": self.N,
            "lam": self.lam,
            "rho": self.rho,
            "deff": self.deff,
            "ess_gain": self.ess_gain,
            "method": self.method,
            "alpha": self.alpha,
        }


# --------------------------------------------------------------------------------------------- validation


def _is_number(x: object) -> bool:
    """A real number, numpy scalars included; bool excluded (True is not a level or a pseudo-count)."""
    return isinstance(x, int | float | np.integer | np.floating) and not isinstance(x, bool)


def _check_alpha(alpha: float) -> None:
    if not (_is_number(alpha) and 0.0 < alpha < 1.0):
        raise ValueError(f"alpha must be in (0, 1), got {alpha!r}")


def _check_method(method: str) -> None:
    if method not in METHODS:
        raise ValueError(f"unknown method {method!r}: expected one of {', '.join(map(repr, METHODS))}")


def _check_prior(prior: float) -> None:
    if not (_is_number(prior) and math.isfinite(prior) and prior >= 0.0):
        raise ValueError(f"prior must be a finite pseudo-count >= 0, got {prior!r}")


def _check_lam(lam: float | None) -> None:
    if lam is not None and not (_is_number(lam) and 0.0 <= lam <= 1.0):
        raise ValueError(f"lam must be in [0, 1] or None (power-tuned), got {lam!r}")


def _as_unit(values: ArrayLike, name: str, ndim: int) -> Array:
    """``values`` as float64 with ``ndim`` axes, every entry in [0, 1] (binary outcomes or fractional scores)."""
    arr = np.asarray(values, dtype=np.float64)
    if arr.ndim != ndim:
        raise ValueError(f"{name} must be {ndim}-D, got shape {arr.shape}")
    # NaN fails both comparisons, so this one test also rejects missing values.
    bad = ~((arr >= 0.0) & (arr <= 1.0))
    if bad.any():
        first = arr[bad].flat[0]
        raise ValueError(f"{name} must hold values in [0, 1] with no NaN (outcomes or scores), found {float(first)!r}")
    return arr


def normal_quantile(alpha: float) -> float:
    """z with P(|Z| ≤ z) = 1 − alpha: the two-sided normal quantile (scipy's norm.ppf(1 − alpha/2))."""
    _check_alpha(alpha)
    return NormalDist().inv_cdf(1.0 - alpha / 2.0)


# ------------------------------------------------------------------------------------------------ moments


def _smoothed_moments(Y: Array, F: Array, prior: float) -> tuple[Array, Array, Array, Array, Array]:
    """Weighted (ddof 0) mean_y, mean_f, var_y, var_f, cov_yf of the rows of (Y, F) plus four pseudo-pairs.

    The pseudo-pairs (0,0), (0,1), (1,0), (1,1), each of weight ``prior``, are a weak Dirichlet prior on
    the 2×2 table: a pilot of 10 successes out of 10 has no sample variance, but its success rate is not
    known exactly, and the smoothed variance says so. Because the pseudo-pairs form a product grid their
    contributions to the centred sums factorise, which keeps this O(n) per row without building the table.
    """
    n = Y.shape[1]
    w = n + 4.0 * prior
    my = (Y.sum(axis=1) + 2.0 * prior) / w
    mf = (F.sum(axis=1) + 2.0 * prior) / w
    dy = Y - my[:, None]
    df = F - mf[:, None]
    # Σ over the pseudo-pairs of (a − m)² = 2·(m² + (1 − m)²) per axis; of (a − my)(b − mf) = (1 − 2my)(1 − 2mf).
    var_y = ((dy * dy).sum(axis=1) + 2.0 * prior * (my**2 + (1.0 - my) ** 2)) / w
    var_f = ((df * df).sum(axis=1) + 2.0 * prior * (mf**2 + (1.0 - mf) ** 2)) / w
    cov = ((dy * df).sum(axis=1) + prior * (1.0 - 2.0 * my) * (1.0 - 2.0 * mf)) / w
    return my, mf, var_y, var_f, cov


def _pooled_variance(F: Array, U: Array, ddof: int) -> Array:
    """Variance of each row of the concatenation [F, U], without building it (U can be ~10⁸ floats)."""
    n, N = F.shape[1], U.shape[1]
    m = (F.sum(axis=1) + U.sum(axis=1)) / (n + N)
    ss = ((F - m[:, None]) ** 2).sum(axis=1) + ((U - m[:, None]) ** 2).sum(axis=1)
    out: Array = ss / (n + N - ddof)
    return out


def _constant_rows(F: Array, U: Array) -> NDArray[np.bool_]:
    """Rows where every prediction (labelled and unlabelled) is the same value.

    Tested exactly (max == min) rather than as variance == 0, which rounding can miss; there the
    predictions carry no information and λ = 0 (ppi_py would divide 0 by 0 and return NaN).
    """
    hi = np.maximum(F.max(axis=1), U.max(axis=1))
    lo = np.minimum(F.min(axis=1), U.min(axis=1))
    out: NDArray[np.bool_] = hi == lo
    return out


def _tuned_lambda(cov: Array, var_pred: Array, constant: NDArray[np.bool_], n: int, N: int) -> Array:
    """λ* = Cov(y, f) / ((1 + n/N)·Var(f)) clipped to [0, 1], as ppi_py's _calc_lam_glm(clip=True).

    The clip at 0 means an anti-correlated predictor is ignored rather than used with a negative sign;
    the clip at 1 keeps θ̂ between the classical estimate and plain PPI.
    """
    denom = (1.0 + n / N) * var_pred
    safe = np.where(constant, 1.0, denom)
    lam = np.where(constant, 0.0, cov / safe)
    out: Array = np.clip(lam, 0.0, 1.0)
    return out


def _design_effect(v_ppi: Array, v_classical: Array) -> Array:
    """V_ppi / V_classical; 1 where the real outcomes have no variance (nothing for PPI to reduce)."""
    zero = v_classical <= 0.0
    out: Array = np.where(zero, 1.0, v_ppi / np.where(zero, 1.0, v_classical))
    return out


def _correlation(var_y: Array, var_f: Array, cov: Array) -> Array:
    """Pearson correlation, NaN where either variance is 0."""
    prod = var_y * var_f
    ok = prod > 0.0
    out: Array = np.where(ok, cov / np.sqrt(np.where(ok, prod, 1.0)), np.nan)
    return np.clip(out, -1.0, 1.0)


def smoothed_correlation(y: ArrayLike, f: ArrayLike, *, prior: float = DEFAULT_PRIOR) -> float | None:
    """corr(y, f) from the labelled 2×2 table smoothed by ``prior`` pseudo-counts per cell; None if undefined."""
    _check_prior(prior)
    yy, ff = _paired(y, f)
    _check_sizes(yy.size, None, "wilson")
    _, _, var_y, var_f, cov = _smoothed_moments(yy[None, :], ff[None, :], prior)
    rho = float(_correlation(var_y, var_f, cov)[0])
    return None if math.isnan(rho) else rho


# ---------------------------------------------------------------------------------------------- intervals


def _wilson(centre: Array, n_eff: Array, z: float) -> tuple[Array, Array]:
    """Wilson score bounds for a [0, 1] mean ``centre`` observed with (effective) sample size ``n_eff``.

    ``n_eff`` may be inf (a predictor that removes all variance): the interval then collapses to the
    centre, which numpy evaluates without a warning because z²/inf = 0.
    """
    c = np.clip(centre, 0.0, 1.0)
    z2n = z * z / n_eff
    d = 1.0 + z2n
    m = (c + z2n / 2.0) / d
    h = z * np.sqrt(c * (1.0 - c) / n_eff + z * z / (4.0 * n_eff**2)) / d
    return np.clip(m - h, 0.0, 1.0), np.clip(m + h, 0.0, 1.0)


def _wilson_batch(
    Y: Array, F: Array, U: Array, alpha: float, prior: float, lam_fixed: float | None
) -> dict[str, Array]:
    """The wilson method: PPI++ estimate, Wilson interval at n_eff = n·V_classical/V_ppi (smoothed table)."""
    n, N = Y.shape[1], U.shape[1]
    z = normal_quantile(alpha)
    _, _, var_y, var_f, cov = _smoothed_moments(Y, F, prior)
    # Var of all predictions, unweighted and ddof 0: the unlabelled ones are not smoothed because f_unlabeled
    # is what the estimate averages, and at N ≫ n its variance is well determined without a prior.
    var_u = _pooled_variance(F, U, ddof=0)
    lam = _tuned_lambda(cov, var_u, _constant_rows(F, U), n, N) if lam_fixed is None else np.full(Y.shape[0], lam_fixed)
    mean_u = U.mean(axis=1)
    estimate = lam * mean_u + (Y - lam[:, None] * F).mean(axis=1)
    v_ppi = (var_y - 2.0 * lam * cov + lam**2 * var_f) / n + lam**2 * var_u / N
    v_classical = var_y / n
    deff = _design_effect(v_ppi, v_classical)
    with np.errstate(divide="ignore"):
        n_eff = n / deff  # inf where deff == 0 (only reachable with prior = 0)
    lower, upper = _wilson(estimate, n_eff, z)
    y_mean = Y.mean(axis=1)
    c_lower, c_upper = _wilson(y_mean, np.full(Y.shape[0], float(n)), z)
    with np.errstate(divide="ignore"):
        ess_gain = 1.0 / deff
    return {
        "estimate": estimate,
        "lower": lower,
        "upper": upper,
        "classical_estimate": y_mean,
        "classical_lower": c_lower,
        "classical_upper": c_upper,
        "lam": lam,
        "deff": deff,
        "ess_gain": ess_gain,
        "rho": _correlation(var_y, var_f, cov),
    }


def _wald_batch(Y: Array, F: Array, U: Array, alpha: float, lam_fixed: float | None) -> dict[str, Array]:
    """ppi_py.ppi_mean_ci(Y, F, U, alpha=alpha) (lam=None) and classical_mean_ci(Y, alpha=alpha), row by row.

    ppi_py first centres the gradients at the λ = 1 estimate; covariances are shift-invariant, so the
    centring drops out and λ is Cov_ddof0(y, f)·2 / (2·(1 + n/N)·Var_ddof1([f, f_unlabeled])).
    """
    n, N = Y.shape[1], U.shape[1]
    z = normal_quantile(alpha)
    y_mean, f_mean = Y.mean(axis=1), F.mean(axis=1)
    dy, df = Y - y_mean[:, None], F - f_mean[:, None]
    var_y = (dy * dy).mean(axis=1)
    cov = (dy * df).mean(axis=1)
    if lam_fixed is None:
        lam = _tuned_lambda(cov, _pooled_variance(F, U, ddof=1), _constant_rows(F, U), n, N)
    else:
        lam = np.full(Y.shape[0], lam_fixed)
    mean_u = U.mean(axis=1)
    var_u = ((U - mean_u[:, None]) ** 2).mean(axis=1)
    rect = Y - lam[:, None] * F
    rect_mean = rect.mean(axis=1)
    estimate = lam * mean_u + rect_mean
    var_rect = ((rect - rect_mean[:, None]) ** 2).mean(axis=1)
    v_ppi = lam**2 * var_u / N + var_rect / n
    v_classical = var_y / n
    se, c_se = np.sqrt(v_ppi), np.sqrt(v_classical)
    deff = _design_effect(v_ppi, v_classical)
    with np.errstate(divide="ignore"):
        ess_gain = 1.0 / deff
    var_f = (df * df).mean(axis=1)
    return {
        "estimate": estimate,
        "lower": estimate - z * se,
        "upper": estimate + z * se,
        "classical_estimate": y_mean,
        "classical_lower": y_mean - z * c_se,
        "classical_upper": y_mean + z * c_se,
        "lam": lam,
        "deff": deff,
        "ess_gain": ess_gain,
        "rho": _correlation(var_y, var_f, cov),
    }


def _check_sizes(n: int, N: int | None, method: str) -> None:
    if n == 0:
        raise ValueError("no paired subtasks (n = 0): PPI needs at least one real outcome")
    if N == 0:
        raise ValueError(
            "no imagined-only subtasks (N = 0): PPI needs unlabelled predictions; "
            "use classical_mean for the real outcomes alone"
        )
    if method == "wald" and n < 2:
        raise ValueError(f"wald needs n ≥ 2 paired subtasks (its standard error is 0 at n = 1), got n = {n}")


def ppi_mean_batch(
    Y: ArrayLike,
    F: ArrayLike,
    U: ArrayLike,
    *,
    alpha: float = DEFAULT_ALPHA,
    method: str = "wilson",
    prior: float = DEFAULT_PRIOR,
    lam: float | None = None,
) -> dict[str, Array]:
    """PPI++ intervals for D independent problems at once: Y, F of shape (D, n), U of shape (D, N).

    Returns arrays of shape (D,) under the keys estimate, lower, upper, classical_estimate,
    classical_lower, classical_upper, lam, deff, ess_gain and rho (NaN where undefined).
    ``prior`` is used by the wilson method only. ``lam`` fixes λ instead of tuning it (as ppi_py's ``lam``:
    1 is plain PPI, 0 the classical estimate); a fixed λ makes θ̂ exactly unbiased, whereas the tuned λ,
    being estimated from the same labelled pairs, leaves an O(1/n) bias (~0.007 at n = 20 for a predictor
    that says "success" 30 % too often, a tenth of θ̂'s standard deviation there).
    """
    _check_alpha(alpha)
    _check_method(method)
    _check_prior(prior)
    _check_lam(lam)
    y, f, u = _as_unit(Y, "Y", 2), _as_unit(F, "F", 2), _as_unit(U, "U", 2)
    if y.shape != f.shape:
        raise ValueError(f"Y and F must have the same shape (paired subtasks), got {y.shape} and {f.shape}")
    if u.shape[0] != y.shape[0]:
        raise ValueError(f"U must have as many rows as Y, got {u.shape[0]} and {y.shape[0]}")
    _check_sizes(y.shape[1], u.shape[1], method)
    if method == "wald":
        return _wald_batch(y, f, u, alpha, lam)
    return _wilson_batch(y, f, u, alpha, prior, lam)


def _paired(y: ArrayLike, f: ArrayLike) -> tuple[Array, Array]:
    yy, ff = _as_unit(y, "y", 1), _as_unit(f, "f", 1)
    if yy.shape != ff.shape:
        raise ValueError(f"y and f must have the same length (paired subtasks), got {yy.size} and {ff.size}")
    return yy, ff


def ppi_mean(
    y: ArrayLike,
    f: ArrayLike,
    f_unlabeled: ArrayLike,
    *,
    alpha: float = DEFAULT_ALPHA,
    method: str = "wilson",
    prior: float = DEFAULT_PRIOR,
    lam: float | None = None,
) -> PPIEstimate:
    """The prediction-powered interval of E[y] from paired (y, f) and imagined-only predictions ``f_unlabeled``.

    Values must lie in [0, 1]: binary outcomes or fractional scores (e.g. a mean over judges).
    ``prior`` and ``lam`` are as in ``ppi_mean_batch``.
    """
    _check_alpha(alpha)
    _check_method(method)
    _check_prior(prior)
    _check_lam(lam)
    yy, ff = _paired(y, f)
    uu = _as_unit(f_unlabeled, "f_unlabeled", 1)
    _check_sizes(yy.size, uu.size, method)
    r = ppi_mean_batch(yy[None, :], ff[None, :], uu[None, :], alpha=alpha, method=method, prior=prior, lam=lam)
    rho = float(r["rho"][0])
    return PPIEstimate(
        ppi=Interval(float(r["estimate"][0]), float(r["lower"][0]), float(r["upper"][0])),
        classical=Interval(
            float(r["classical_estimate"][0]), float(r["classical_lower"][0]), float(r["classical_upper"][0])
        ),
        n=int(yy.size),
        N=int(uu.size),
        lam=float(r["lam"][0]),
        rho=None if math.isnan(rho) else rho,
        deff=float(r["deff"][0]),
        ess_gain=float(r["ess_gain"][0]),
        method=method,
        alpha=float(alpha),
    )


def classical_mean(y: ArrayLike, *, alpha: float = DEFAULT_ALPHA, method: str = "wilson") -> Interval:
    """The interval of E[y] from real outcomes alone (Wilson score, or ppi_py's classical_mean_ci for wald)."""
    _check_alpha(alpha)
    _check_method(method)
    yy = _as_unit(y, "y", 1)
    n = yy.size
    if n == 0:
        raise ValueError("no real outcomes (n = 0): an interval needs at least one")
    _check_sizes(n, None, method)
    z = normal_quantile(alpha)
    mean = float(yy.mean())
    if method == "wald":
        half = z * float(yy.std()) / math.sqrt(n)
        return Interval(mean, mean - half, mean + half)
    lo, hi = _wilson(np.array([mean]), np.array([float(n)]), z)
    return Interval(mean, float(lo[0]), float(hi[0]))


# --------------------------------------------------------------------------------------------- difference


def difference(a: PPIEstimate, b: PPIEstimate, which: str = "ppi") -> Interval:
    """Interval of θ_a − θ_b from two independent estimates (checkpoint ranking), at their common alpha.

    wilson: Newcombe's hybrid score interval (Newcombe 1998, method 10), which combines each side's
    distance from its estimate to its Wilson bound; it keeps the Wilson intervals' asymmetry near 0 and 1,
    where a symmetric difference of Walds would again undercover. The estimates are clipped to [0, 1]
    here, so the interval contains its estimate.
    wald: d ± z·sqrt(se_a² + se_b²) with se = half_width / z.
    """
    if which not in ("ppi", "classical"):
        raise ValueError(f"which must be 'ppi' or 'classical', got {which!r}")
    if a.method != b.method:
        raise ValueError(f"difference needs estimates of one method, got {a.method!r} and {b.method!r}")
    if a.alpha != b.alpha:
        raise ValueError(f"difference needs estimates at one alpha, got {a.alpha!r} and {b.alpha!r}")
    ia, ib = (a.ppi, b.ppi) if which == "ppi" else (a.classical, b.classical)
    if a.method == "wald":
        z = normal_quantile(a.alpha)
        d = ia.estimate - ib.estimate
        half = z * math.hypot(ia.half_width / z, ib.half_width / z)
        return Interval(d, d - half, d + half)
    ea, eb = _clip01(ia.estimate), _clip01(ib.estimate)
    d = ea - eb
    lower = d - math.hypot(ea - ia.lower, ib.upper - eb)
    upper = d + math.hypot(ia.upper - ea, eb - ib.lower)
    return Interval(d, lower, upper)


def _clip01(x: float) -> float:
    return min(1.0, max(0.0, x))


# ------------------------------------------------------------------------------------------------ formulas


def _check_formula_args(rho: float, n: int, N: float) -> None:
    if not -1.0 <= rho <= 1.0:
        raise ValueError(f"rho must be in [-1, 1], got {rho!r}")
    if n < 1:
        raise ValueError(f"n must be >= 1, got {n!r}")
    if not N >= 0:
        raise ValueError(f"N must be >= 0, got {N!r}")


def _imagined_share(rho: float, n: int, N: float) -> float:
    """ρ₊²·N/(N + n): the share of Var(y)/n that the imagined runs remove at λ*.

    ρ is clipped at 0 because λ is: an anti-correlated predictor gets λ = 0 and removes nothing.
    N = inf is the limit of unlimited imagined runs (share ρ₊²).
    """
    r2 = max(rho, 0.0) ** 2
    return r2 if math.isinf(N) else r2 * N / (N + n)


def width_ratio_formula(rho: float, n: int, N: float) -> float:
    """PPI / classical interval width at the optimal λ: sqrt(1 − ρ²·N/(N + n))."""
    _check_formula_args(rho, n, N)
    return math.sqrt(1.0 - _imagined_share(rho, n, N))


def ess_gain_formula(rho: float, n: int, N: float) -> float:
    """Effective labelled samples per real trial at the optimal λ: 1/(1 − ρ²·N/(N + n)); inf at ρ = 1, N = inf."""
    _check_formula_args(rho, n, N)
    rest = 1.0 - _imagined_share(rho, n, N)
    return math.inf if rest <= 0.0 else 1.0 / rest


__all__ = [
    "METHODS",
    "Interval",
    "PPIEstimate",
    "classical_mean",
    "difference",
    "ess_gain_formula",
    "normal_quantile",
    "ppi_mean",
    "ppi_mean_batch",
    "smoothed_correlation",
    "width_ratio_formula",
]
