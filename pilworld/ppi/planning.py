"""How many real trials a checkpoint needs, with and without imagined runs (``pilworld plan-trials``).

At the optimal λ the PPI++ variance of a success rate p is p(1 − p)/n · (1 − ρ²·N/(N + n)), ρ being the
correlation of real and imagined outcomes (see ``pilworld.ppi.estimator``). For a target half-width h at
level 1 − α the smallest n with z·sqrt(that) ≤ h is the number of real trials to run; imagined runs
are cheap, so the plan lists it for several N and says how many imagined runs capture most of the saving.
This is the normal approximation: at the small n it sometimes gives, the Wilson interval of the estimator
is a little wider, so treat a plan under ~20 trials as a floor.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import ArrayLike

from pilworld.ppi.estimator import DEFAULT_PRIOR, normal_quantile, smoothed_correlation

DEFAULT_GRID = (50, 100, 200, 400, 1000, 4000)
MIN_TRIALS = 2
# p(1 − p) is computed with p clipped to this range: a pilot that saw 0/10 or 10/10 successes has a
# p(1 − p) of 0, which would plan 2 trials, yet its true rate is not known to be exactly 0 or 1.
P_RANGE = (0.02, 0.98)
WORTH_FRACTION = 0.9  # imagined_worth: the N that reaches this share of the largest possible saving
WORTH_START = 25
_WORTH_DOUBLINGS = 40  # 25·2⁴⁰ imagined runs: far past any practical N, so the search always ends


def _check_plan_args(p: float, rho: float, half_width: float, alpha: float) -> None:
    if not 0.0 <= p <= 1.0:
        raise ValueError(f"p must be in [0, 1], got {p!r}")
    if not -1.0 <= rho <= 1.0:
        raise ValueError(f"rho must be in [-1, 1], got {rho!r}")
    if not 0.0 < half_width <= 0.5:
        raise ValueError(f"half_width must be in (0, 0.5], got {half_width!r}")
    normal_quantile(alpha)  # validates alpha


def _half_width(pq: float, r2: float, n: int, N: float | None, z: float) -> float:
    """z·sqrt(pq/n · (1 − ρ₊²·N/(N + n))): the PPI++ half-width at the optimal λ (N None: classical)."""
    if N is None or N == 0:
        share = 0.0
    elif math.isinf(N):
        share = r2
    else:
        share = r2 * N / (N + n)
    return z * math.sqrt(pq / n * (1.0 - share))


def real_trials_needed(p: float, rho: float, half_width: float, N: float | None, *, alpha: float = 0.05) -> int:
    """Smallest n ≥ 2 whose PPI++ half-width with N imagined runs is ≤ ``half_width``.

    N = None plans without imagined runs (classical); N = math.inf is the limit of unlimited ones
    (variance factor 1 − ρ²). A negative ρ counts as 0, because the estimator clips λ at 0.
    """
    _check_plan_args(p, rho, half_width, alpha)
    if N is not None and not N >= 0:
        raise ValueError(f"N must be >= 0, math.inf or None, got {N!r}")
    z = normal_quantile(alpha)
    pc = min(max(p, P_RANGE[0]), P_RANGE[1])
    pq = pc * (1.0 - pc)
    r2 = max(rho, 0.0) ** 2
    # The half-width falls strictly with n (d/dn of (a + n)/(n(N + n)) < 0), and the classical n bounds
    # the answer from above, so an integer bisection on the exact predicate finds the smallest n.
    lo, hi = MIN_TRIALS, max(MIN_TRIALS, math.ceil(z * z * pq / half_width**2) + 1)
    while _half_width(pq, r2, hi, None, z) > half_width:  # guards the ceil against rounding
        hi *= 2
    if _half_width(pq, r2, lo, N, z) <= half_width:
        return lo
    while hi - lo > 1:  # invariant: lo fails, hi passes
        mid = (lo + hi) // 2
        if _half_width(pq, r2, mid, N, z) <= half_width:
            hi = mid
        else:
            lo = mid
    return hi


@dataclass(frozen=True)
class TrialPlan:
    """Real trials needed for a target half-width, without and with imagined runs."""

    half_width: float
    alpha: float
    p: float
    rho: float
    classical: int  # real trials without imagined ones
    with_imagined: dict[int, int]  # N → real trials needed
    limit: int  # N → ∞
    imagined_worth: int  # smallest N (doubling from 25) reaching 90 % of the largest saving; 0 if that is < 1

    def to_json(self) -> dict[str, Any]:
        return {
            "half_width": self.half_width,
            "alpha": self.alpha,
            "p": self.p,
            "rho": self.rho,
            "classical": self.classical,
            "with_imagined": {str(k): v for k, v in self.with_imagined.items()},
            "limit": self.limit,
            "imagined_worth": self.imagined_worth,
        }


def _imagined_worth(p: float, rho: float, half_width: float, alpha: float, classical: int, limit: int) -> int:
    """Smallest N in 25, 50, 100, … whose saving is ≥ 90 % of ``classical − limit``; 0 if that saving is < 1.

    A doubling grid because the saving grows like N/(N + n): the useful question is the order of magnitude
    of imagined runs worth generating, not an exact N.
    """
    saving = classical - limit
    if saving < 1:
        return 0
    N = WORTH_START
    for _ in range(_WORTH_DOUBLINGS):
        if classical - real_trials_needed(p, rho, half_width, N, alpha=alpha) >= WORTH_FRACTION * saving:
            return N
        N *= 2
    return N


def plan_trials(
    p: float,
    rho: float,
    half_width: float,
    *,
    alpha: float = 0.05,
    grid: Sequence[int] = DEFAULT_GRID,
) -> TrialPlan:
    """The real trials a target ``half_width`` needs, for each N in ``grid`` and in the limits N = 0, ∞."""
    _check_plan_args(p, rho, half_width, alpha)
    for N in grid:
        if isinstance(N, bool) or not isinstance(N, int) or N < 1:
            raise ValueError(f"grid must hold integers >= 1, got {N!r}")
    classical = real_trials_needed(p, rho, half_width, None, alpha=alpha)
    limit = real_trials_needed(p, rho, half_width, math.inf, alpha=alpha)
    return TrialPlan(
        half_width=half_width,
        alpha=alpha,
        p=p,
        rho=rho,
        classical=classical,
        with_imagined={N: real_trials_needed(p, rho, half_width, N, alpha=alpha) for N in grid},
        limit=limit,
        imagined_worth=_imagined_worth(p, rho, half_width, alpha, classical, limit),
    )


def pilot_agreement(y: ArrayLike, f: ArrayLike) -> tuple[float, float]:
    """(p̂, ρ̂) from a pilot of paired real / imagined outcomes, for ``plan_trials``.

    ρ̂ uses the estimator's smoothed 2×2 table, so a small pilot does not plan with a perfect ρ = 1
    it happened to see; ρ̂ = 0 (plan as if the imagined runs did not help) where it is undefined.
    """
    rho = smoothed_correlation(y, f, prior=DEFAULT_PRIOR)  # validates y and f, and that n ≥ 1
    return float(np.mean(np.asarray(y, dtype=np.float64))), 0.0 if rho is None else rho
