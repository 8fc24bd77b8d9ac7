"""Prediction-powered inference: real success rates sharpened by imagined (world-model) runs (PPI++).

``ppi_mean`` gives the PPI++ interval of one checkpoint's real success rate from paired real / imagined
outcomes plus imagined-only runs; ``difference`` compares two checkpoints; ``plan_trials`` says how
many real trials a target interval width needs with and without imagined runs.
"""

from pilworld.ppi.estimator import (
    METHODS,
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
from pilworld.ppi.planning import TrialPlan, pilot_agreement, plan_trials, real_trials_needed

__all__ = [
    "METHODS",
    "Interval",
    "PPIEstimate",
    "TrialPlan",
    "classical_mean",
    "difference",
    "ess_gain_formula",
    "normal_quantile",
    "pilot_agreement",
    "plan_trials",
    "ppi_mean",
    "ppi_mean_batch",
    "real_trials_needed",
    "smoothed_correlation",
    "width_ratio_formula",
]
