"""``pilworld bench ppi``: are the PPI++ intervals valid, and how much narrower are they? Measured, not assumed.

On the simulated rig the real branch can be rerun at will, so a pool of paired subtasks per checkpoint
(real outcome y by the simulator's checker, imagined outcome f by the image-only judge on the world
model's branch) stands for the population. Each draw takes n paired subtasks and N imagined-only ones
(their f only) per checkpoint, with replacement, so the pool's real success rate is the exact truth
the intervals must cover. For n ∈ {10, 20, 40}, N ∈ {100, 400} and every predictor:

* ``shipped`` — the shipped world model's own verdicts f from the pool;
* ``agreement_a`` — a synthetic predictor that agrees with the real outcome with probability a
  (0.5: pure noise, 0.7, 0.9) on the same real outcomes, to show the gain against agreement
  independently of today's model;

it reports the empirical coverage of the nominal 95 % intervals (PPI and classical, for the default
``wilson`` method and for ``wald`` = ppi_py's ``ppi_mean_ci``), mean widths, the measured width ratio
PPI / classical against the PPI++ variance formula sqrt(1 − ρ²·N/(N + n)), and the effective sample
size gain (measured as (classical width / PPI width)², and by formula).
"""

from __future__ import annotations

import argparse
import json
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from pilworld.bench.flags import add_json
from pilworld.bench.output import Column, emit, num, table
from pilworld.options.bounds import at_least_one
from pilworld.ppi.estimator import ess_gain_formula, ppi_mean_batch, width_ratio_formula
from pilworld.ppi.outcomes import read_run_outcomes

POOL_SEED0 = 7_000_000  # layouts of the pool: unseen in training (0–19) and by the other benchmarks
NS = (10, 20, 40)
BIG_NS = (100, 400)
AGREEMENTS = (0.5, 0.7, 0.9)
COVERAGE_BAND = (0.93, 0.97)
RATIO_TOLERANCE = 0.10

Array = NDArray[np.float64]


@dataclass(frozen=True)
class Population:
    """One checkpoint's pool: real outcomes y and the shipped model's imagined outcomes f, per pair."""

    checkpoint: str
    y: Array
    f: Array

    @property
    def truth(self) -> float:
        return float(self.y.mean())


def _corr(y: Array, f: Array) -> float:
    if y.std() == 0 or f.std() == 0:
        return 0.0
    return float(np.corrcoef(y, f)[0, 1])


def synthetic_rho(p: float, a: float) -> float:
    """Population correlation of y ~ Bernoulli(p) and f = y with probability a, else 1 − y."""
    pf = a * p + (1 - a) * (1 - p)
    denom = p * (1 - p) * pf * (1 - pf)
    return 0.0 if denom <= 0 else float((a * p - p * pf) / np.sqrt(denom))


def _draw(
    pop: Population, predictor: str, n: int, N: int, draws: int, rng: np.random.Generator
) -> tuple[Array, Array, Array, float]:
    """Y, F (draws × n) and U (draws × N) for one checkpoint, and the predictor's population ρ."""
    size = len(pop.y)
    lab = rng.integers(0, size, (draws, n))
    unl = rng.integers(0, size, (draws, N))
    Y = pop.y[lab]
    if predictor == "shipped":
        return Y, pop.f[lab], pop.f[unl], _corr(pop.y, pop.f)
    a = float(predictor.removeprefix("agreement_"))
    flip_l = rng.random((draws, n)) >= a
    flip_u = rng.random((draws, N)) >= a
    F = np.where(flip_l, 1.0 - Y, Y)
    U = np.where(flip_u, 1.0 - pop.y[unl], pop.y[unl])
    return Y, F, U, synthetic_rho(pop.truth, a)


def evaluate_setting(
    pops: list[Population], predictor: str, n: int, N: int, draws: int, method: str, seed: int
) -> dict[str, Any]:
    """Coverage, widths, width ratio and gain of one (predictor, n, N, method), pooled over checkpoints."""
    rng = np.random.default_rng(seed)
    cover_ppi = cover_cl = 0
    w_ppi = w_cl = w_pred = 0.0
    gains: list[float] = []
    per_ckpt = {}
    for pop in pops:
        Y, F, U, rho = _draw(pop, predictor, n, N, draws, rng)
        r = ppi_mean_batch(Y, F, U, method=method)
        t = pop.truth
        c_ppi = int(np.sum((r["lower"] <= t) & (t <= r["upper"])))
        c_cl = int(np.sum((r["classical_lower"] <= t) & (t <= r["classical_upper"])))
        wp = float(np.mean(r["upper"] - r["lower"]))
        wc = float(np.mean(r["classical_upper"] - r["classical_lower"]))
        cover_ppi += c_ppi
        cover_cl += c_cl
        w_ppi += wp
        w_cl += wc
        w_pred += wc * width_ratio_formula(rho, n, N)
        gains.append(float(np.mean(r["ess_gain"])))
        per_ckpt[pop.checkpoint] = {
            "truth": round(t, 4),
            "rho": round(rho, 4),
            "coverage_ppi": round(c_ppi / draws, 4),
            "coverage_classical": round(c_cl / draws, 4),
            "width_ppi": round(wp, 4),
            "width_classical": round(wc, 4),
            "width_ratio_formula": round(width_ratio_formula(rho, n, N), 4),
            "ess_gain_formula": round(ess_gain_formula(rho, n, N), 4),
        }
    total = draws * len(pops)
    # A pool whose real outcomes never vary gives Wald intervals of width 0: no ratio to speak of.
    ratio = w_ppi / w_cl if w_cl > 0 else None
    predicted = w_pred / w_cl if w_cl > 0 else None

    def r4(x: float | None) -> float | None:
        return None if x is None else round(x, 4)

    return {
        "predictor": predictor,
        "method": method,
        "n": n,
        "N": N,
        "draws_per_checkpoint": draws,
        "intervals": total,
        "coverage_ppi": round(cover_ppi / total, 4),
        "coverage_classical": round(cover_cl / total, 4),
        "mean_width_ppi": round(w_ppi / len(pops), 4),
        "mean_width_classical": round(w_cl / len(pops), 4),
        "width_ratio": r4(ratio),
        "width_ratio_formula": r4(predicted),
        "width_ratio_vs_formula": r4(ratio / predicted) if ratio and predicted else None,
        "ess_gain_measured": r4((1.0 / ratio) ** 2) if ratio else None,
        "ess_gain_formula": r4(1.0 / predicted**2) if predicted else None,
        "ess_gain_estimated": round(float(np.mean(gains)), 4),
        "checkpoints": per_ckpt,
    }


def pool_populations(pool: str | Path) -> list[Population]:
    """Each checkpoint's (y, f) pairs from a judged paired run (y: the simulator's checker, f: the judge)."""
    outcomes = read_run_outcomes(pool, imagined=[])
    pops = [
        Population(c, np.asarray(o.y, dtype=np.float64), np.asarray(o.f, dtype=np.float64))
        for c, o in sorted(outcomes.by_checkpoint.items())
        if o.y
    ]
    if not pops:
        raise ValueError(f"--pool: {pool} has no pair with a real and an imagined verdict (judge it first)")
    return pops


def make_pool(out: Path, *, subtasks: int, progress: bool) -> Path:
    """The pool as a judged paired run on the simulated rig (every task × checkpoint; resumable)."""
    from pilworld.demo import run_demo
    from simrig.files import SIM_RIG

    rig = SIM_RIG
    run_demo(out, rig=rig, full=True, subtasks=subtasks, seed=POOL_SEED0, progress=progress)
    return out


def run_ppi_bench(
    *,
    pool: str | Path | None = None,
    out: str | Path = "bench_runs/ppi",
    quick: bool = False,
    draws: int | None = None,
    seed: int = 0,
    progress: bool = True,
) -> dict[str, Any]:
    """Every setting for both methods; ``pool`` reuses a judged paired run instead of running one."""
    t0 = time.monotonic()
    subtasks = 4 if quick else 20
    root = Path(pool) if pool is not None else make_pool(Path(out) / "pool", subtasks=subtasks, progress=progress)
    pops = pool_populations(root)
    draws = draws or (200 if quick else 2000)
    predictors = ["shipped", *[f"agreement_{a}" for a in AGREEMENTS]]
    rows = []
    k = 0
    for method in ("wilson", "wald"):
        for predictor in predictors:
            for n in NS:
                for N in BIG_NS:
                    rows.append(evaluate_setting(pops, predictor, n, N, draws, method, seed + k))
                    k += 1
    wilson = [r for r in rows if r["method"] == "wilson"]
    lo, hi = COVERAGE_BAND
    headline = next(r for r in wilson if r["predictor"] == "agreement_0.9" and r["n"] == 20 and r["N"] == 400)
    checks = {
        "coverage_in_band": all(lo <= r["coverage_ppi"] <= hi for r in wilson),
        "coverage_band": list(COVERAGE_BAND),
        "coverage_min": min(r["coverage_ppi"] for r in wilson),
        "coverage_max": max(r["coverage_ppi"] for r in wilson),
        "width_ratio_within_10pct": all(
            r["width_ratio_vs_formula"] is not None and abs(r["width_ratio_vs_formula"] - 1) <= RATIO_TOLERANCE
            for r in wilson
        ),
        "width_ratio_vs_formula_worst": max(
            (r["width_ratio_vs_formula"] or 0.0 for r in wilson), key=lambda v: abs(v - 1)
        ),
        "ess_gain_agreement_0.9_n20_N400": {
            "measured": headline["ess_gain_measured"],
            "formula": headline["ess_gain_formula"],
            "estimated": headline["ess_gain_estimated"],
        },
        "wald_coverage_min": min(r["coverage_ppi"] for r in rows if r["method"] == "wald"),
    }
    return {
        "pool": str(root),
        "pool_pairs": {p.checkpoint: len(p.y) for p in pops},
        "pool_truth": {p.checkpoint: round(p.truth, 4) for p in pops},
        "pool_agreement": {p.checkpoint: round(float(np.mean(p.y == p.f)), 4) for p in pops},
        "pool_rho": {p.checkpoint: round(_corr(p.y, p.f), 4) for p in pops},
        "sampling": "with replacement from the pool (the pool's real success rate is the truth); seed "
        f"{seed}; a fresh synthetic predictor per draw",
        "settings": rows,
        "checks": checks,
        "seconds": round(time.monotonic() - t0, 1),
    }


# The summary table, one row per setting (pilworld/bench/output.py aligns it).
PPI_COLUMNS = (
    Column("method", 7, "method", align="<"),
    Column("predictor", 14, "predictor", align="<", sep=" "),
    Column("n", 3, "n", sep=" "),
    Column("N", 4, "N", sep=" "),
    Column("cov PPI", 8, "coverage_ppi", lambda x: num(x, 3), sep=" "),
    Column("cov cl.", 8, "coverage_classical", lambda x: num(x, 3), sep=" "),
    Column("ratio", 6, "width_ratio", lambda x: num(x, 3), sep=" "),
    Column("formula", 8, "width_ratio_formula", lambda x: num(x, 3), sep=" "),
    Column("ESS gain", 9, "ess_gain_measured", num, sep=" "),
)


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--pool", type=Path, default=None, help="a judged paired run to draw from (default: run one)")
    parser.add_argument("--out", type=Path, default=Path("bench_runs/ppi"), help="where the pool is run (default)")
    parser.add_argument("--draws", type=int, default=None, help="draws per checkpoint and setting (default 2000)")
    parser.add_argument("--seed", type=int, default=0, help="sampling seed (default 0)")
    parser.add_argument("--quick", action="store_true", help="a 60-pair pool and 200 draws (≤ 5 minutes)")
    add_json(parser, "print the whole result as JSON")


def run(args: argparse.Namespace) -> int:
    """The pool, one table row per setting, and the checks."""
    at_least_one(args, "draws")
    r = run_ppi_bench(
        pool=args.pool, out=args.out, quick=args.quick, draws=args.draws, seed=args.seed, progress=not args.json
    )
    lines = [f"pool {r['pool']}: real success rate per checkpoint {r['pool_truth']}, per-pair rho {r['pool_rho']}"]
    lines += table(PPI_COLUMNS, r["settings"], indent="")
    lines.append("checks: " + json.dumps(r["checks"]))
    return emit(args, r, lines)
