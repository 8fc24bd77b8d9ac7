"""The report's charts as PNG bytes (matplotlib, Agg): success scatter and per-frame error curves.

PNG rather than inline SVG: an embedded SVG carries XML namespace URLs, and the report promises no
``http(s)`` reference at all. PNG metadata is stripped for the same reason.
"""

from __future__ import annotations

import io
import math
from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np

SERIES_COLORS = ("#1f77b4", "#d62728", "#2ca02c", "#9467bd", "#ff7f0e", "#8c564b", "#17becf", "#7f7f7f")


def _pyplot() -> Any:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def _png(fig: Any) -> bytes:
    plt = _pyplot()
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=100, bbox_inches="tight", metadata={"Software": None})
    plt.close(fig)
    return buf.getvalue()


def pearson(x: Sequence[float], y: Sequence[float]) -> float | None:
    """Pearson's r, or None with fewer than two points or no spread."""
    a, b = np.asarray(x, dtype=np.float64), np.asarray(y, dtype=np.float64)
    if len(a) < 2 or np.std(a) == 0 or np.std(b) == 0:
        return None
    return float(np.corrcoef(a, b)[0, 1])


def has_fit_line(xs: Sequence[float]) -> bool:
    """A least-squares line needs two points with different real success rates."""
    return len(xs) >= 2 and float(np.std(np.asarray(xs, dtype=np.float64))) > 0


def success_scatter(points: Sequence[tuple[str, float, float]], r: float | None) -> bytes:
    """Real (x) vs imagined (y) success rate per setting, with y = x and the least-squares (Pearson) line.

    ``points``: (label, sr_real, sr_imag); ``r`` the Pearson coefficient shown in the legend.
    """
    plt = _pyplot()
    fig, ax = plt.subplots(figsize=(5.2, 4.6))
    ax.plot([0, 1], [0, 1], linestyle="--", color="#888888", linewidth=1, label="y = x")
    xs = np.array([p[1] for p in points], dtype=np.float64)
    ys = np.array([p[2] for p in points], dtype=np.float64)
    if has_fit_line(list(xs)):
        slope, intercept = np.polyfit(xs, ys, 1)
        line = np.array([0.0, 1.0])
        r_text = f"r = {r:.3f}" if r is not None and math.isfinite(r) else "r undefined"
        ax.plot(line, slope * line + intercept, color="#d62728", linewidth=1.5, label=f"Pearson fit ({r_text})")
    ax.scatter(xs, ys, s=42, color="#1f77b4", edgecolor="white", zorder=3, label="task × checkpoint")
    labels: dict[tuple[float, float], list[str]] = {}  # settings on the same spot share one label
    for label, x, y in points:
        labels.setdefault((x, y), []).append(label)
    for (x, y), names in labels.items():
        ax.annotate(", ".join(names), (x, y), textcoords="offset points", xytext=(5, 4), fontsize=7, color="#333333")
    ax.set(xlim=(-0.03, 1.03), ylim=(-0.03, 1.03), xlabel="success rate, real", ylabel="success rate, imagined")
    ax.set_aspect("equal")
    ax.grid(alpha=0.3)
    ax.legend(loc="upper left", fontsize=8)
    return _png(fig)


def error_curves(
    panels: Mapping[str, Mapping[str, Sequence[float | None]]], title: str, xlabel: str, first_x: int = 0
) -> bytes:
    """One panel per metric (e.g. ``psnr``), one line per series (a view) over the frame index.

    Value ``i`` of a series is drawn at ``first_x + i``.
    """
    plt = _pyplot()
    n = max(1, len(panels))
    fig, axes = plt.subplots(1, n, figsize=(5.2 * n, 3.6), squeeze=False)
    for ax, (metric, series) in zip(axes[0], panels.items(), strict=False):
        for i, (label, values) in enumerate(series.items()):
            y = np.array([np.nan if v is None else float(v) for v in values], dtype=np.float64)
            y[~np.isfinite(y)] = np.nan
            ax.plot(first_x + np.arange(len(y)), y, marker="o", markersize=2.5, linewidth=1.2, label=label,
                    color=SERIES_COLORS[i % len(SERIES_COLORS)])  # fmt: skip
        unit = " [dB]" if "psnr" in metric.lower() else ""
        ax.set(xlabel=xlabel, ylabel=f"{metric.upper()}{unit}")
        ax.grid(alpha=0.3)
        ax.legend(fontsize=8)
    fig.suptitle(title, fontsize=10)
    return _png(fig)


def ppi_intervals(rows: Sequence[tuple[str, Mapping[str, float], Mapping[str, float], int, int]]) -> bytes:
    """Per checkpoint, the classical interval (real trials alone) above the prediction-powered one.

    ``rows``: (checkpoint, classical {estimate, lower, upper}, ppi {…}, n, N).
    """
    plt = _pyplot()
    fig, ax = plt.subplots(figsize=(6.4, 0.65 * len(rows) + 1.2))
    for i, (_, cl, pp, _, _) in enumerate(rows):
        for dy, iv, color, label in ((0.15, cl, "#7f7f7f", "classical (real only)"), (-0.15, pp, "#1f77b4", "PPI++")):
            est = float(iv["estimate"])
            lo, hi = float(iv["lower"]), float(iv["upper"])
            ax.errorbar(
                [min(max(est, 0.0), 1.0)],
                [i + dy],
                xerr=[[max(est - lo, 0.0)], [max(hi - est, 0.0)]],
                fmt="o",
                color=color,
                capsize=3,
                label=label if i == 0 else None,
            )
    ax.set_yticks(range(len(rows)), [f"{c} (n={n}, N={N})" for c, _, _, n, N in rows], fontsize=8)
    ax.invert_yaxis()
    ax.set(xlim=(-0.02, 1.02), xlabel="real success rate (95 % interval)")
    ax.grid(alpha=0.3, axis="x")
    ax.legend(loc="lower center", bbox_to_anchor=(0.5, 1.0), ncol=2, fontsize=8, frameon=False)
    return _png(fig)
