"""Metrics of a paired run (paper appendix "Metric Definitions and Judge Protocol"; docs/metrics.md).

``compute_run_metrics(root)`` / ``write_metrics(root)`` produce ``metrics.json``: SR_real, SR_imag,
|ΔSR| and HFR per task and overall with bootstrap intervals over subtasks, Pearson / Spearman / MMRV
across task × checkpoint settings, and single-step PSNR / SSIM (/ LPIPS) per view and frame index.
"""

from pilworld.metrics.ranking import mmrv, pearson, spearman
from pilworld.metrics.report import compute_run_metrics, write_metrics

__all__ = ["compute_run_metrics", "mmrv", "pearson", "spearman", "write_metrics"]
