"""A robust (Huber) Levenberg-Marquardt over rigid transforms, with a central-difference Jacobian.

scipy is not a dependency, so the hand-eye refinements (:mod:`calib.handeye_refine`) share this small
iteratively-reweighted LM. Each transform is updated as ``R ← exp(ω) R``, ``t ← t + δ`` (6 parameters) and
the problem is re-linearised after every accepted step, so the rotation update stays small. Huber weights
(quadratic below ``huber_px``, linear above) keep a few bad corners from pulling the solution.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from calib.rotations import rigid, rotation_exp

__all__ = ["LmFit", "huber", "levenberg_marquardt", "numeric_jacobian", "update_transforms"]

FloatArray = npt.NDArray[np.float64]
#: ``(n, 2)`` pixel residuals of a list of transforms
Residuals = Callable[[list[FloatArray]], FloatArray]

#: Radians / metres: central differences are then accurate to ~1e-10 of the pixel Jacobian.
STEP: float = 1e-6


def _apply(T: FloatArray, p: npt.ArrayLike) -> FloatArray:
    v = np.asarray(p, dtype=np.float64)
    return rigid(rotation_exp(v[:3]) @ T[:3, :3], T[:3, 3] + v[3:])


def update_transforms(transforms: Sequence[FloatArray], p: FloatArray) -> list[FloatArray]:
    """Each transform ``k`` moved by ``p[6k:6k+6]`` = (ω, δ)."""
    return [_apply(T, p[6 * k : 6 * k + 6]) for k, T in enumerate(transforms)]


def huber(norms: FloatArray, delta: float) -> tuple[float, FloatArray]:
    """Huber cost of the corner error norms and the IRLS weight of each corner."""
    quad = norms <= delta
    cost = float(np.where(quad, 0.5 * norms**2, delta * (norms - 0.5 * delta)).sum())
    weights = np.where(quad, 1.0, delta / np.maximum(norms, 1e-300))
    return cost, weights


def numeric_jacobian(f: Callable[[FloatArray], FloatArray], rows: int, n: int, h: float = STEP) -> FloatArray:
    """``(rows, n)`` central-difference Jacobian of ``f`` (flattened) at parameter 0."""
    J = np.empty((rows, n))
    for k in range(n):
        dp = np.zeros(n)
        dp[k] = h
        J[:, k] = ((f(dp) - f(-dp)) / (2.0 * h)).reshape(-1)
    return J


@dataclass(frozen=True, eq=False)
class LmFit:
    """The fitted transforms, the residuals they leave and how the iteration ended."""

    transforms: list[FloatArray]
    residuals: FloatArray  #: ``(n, 2)`` at the solution
    initial_residuals: FloatArray  #: ``(n, 2)`` at the start
    iterations: int
    converged: bool

    @property
    def rms_px(self) -> float:
        """Plain RMS of the corner errors (not the robust cost)."""
        return math.sqrt(float((self.residuals**2).sum(axis=1).mean()))


def levenberg_marquardt(
    residuals: Residuals,
    start: Sequence[FloatArray],
    huber_px: float,
    max_iterations: int,
    *,
    stop_on_small_step: bool = True,
) -> LmFit:
    """Fit ``start`` (``(4, 4)`` transforms) to minimise the Huber cost of ``residuals``.

    Stops when a step no longer lowers the cost, lowers it by less than 1e-12 relative or, with
    ``stop_on_small_step``, moves no parameter by 1e-12 (then ``converged``).
    """
    Ts = list(start)
    n_par = 6 * len(Ts)

    def moved(Ts: list[FloatArray]) -> Callable[[FloatArray], FloatArray]:
        return lambda p: residuals(update_transforms(Ts, p))

    r = residuals(Ts)
    cost, w = huber(np.linalg.norm(r, axis=1), huber_px)
    initial = r
    lam, converged, it = 1e-3, False, 0
    step: FloatArray = np.zeros(n_par)
    for it in range(1, max_iterations + 1):  # noqa: B007 - `it` is reported
        J = numeric_jacobian(moved(Ts), r.size, n_par)
        wr = np.repeat(w, 2)
        H = J.T @ (wr[:, None] * J)
        g = J.T @ (wr * r.reshape(-1))
        improved, decrease = False, 0.0
        while lam < 1e12:
            step = np.asarray(np.linalg.solve(H + lam * np.diag(np.diag(H) + 1e-12), -g), dtype=np.float64)
            Ts_new = update_transforms(Ts, step)
            r_new = residuals(Ts_new)
            cost_new, w_new = huber(np.linalg.norm(r_new, axis=1), huber_px)
            if cost_new < cost:
                improved = True
                decrease = (cost - cost_new) / max(cost, 1e-300)
                Ts, r, cost, w = Ts_new, r_new, cost_new, w_new
                lam = max(lam / 10.0, 1e-12)
                break
            lam *= 10.0
        if not improved or decrease < 1e-12 or (stop_on_small_step and float(np.abs(step).max()) < 1e-12):
            converged = True
            break
    return LmFit(transforms=Ts, residuals=r, initial_residuals=initial, iterations=it, converged=converged)
