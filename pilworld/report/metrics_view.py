"""Reading ``metrics.json`` tolerantly: numbers, 95 % intervals, settings and per-frame curves.

``metrics.json`` is written by ``pilworld.metrics``; the report only displays it, so it accepts the
layout's variants (a value as a number or ``{"value"|"r"|"rho"|…: x}``, an interval as ``[lo, hi]`` or
``{"lo"|"low"|"lower": …}``) and shows "—" for whatever is missing rather than failing.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from typing import Any

DASH = "—"
VALUE_KEYS = ("value", "estimate", "mean", "r", "rho", "tau", "point")
LOW_KEYS = ("lo", "low", "lower", "l")
HIGH_KEYS = ("hi", "high", "upper", "u")
CURVE_METRICS = ("psnr", "ssim")  # the per-frame curves drawn from single_step
# Path parts of single_step that structure the data rather than name a series.
LABELS = {"frozen": "frozen baseline"}  # series names as shown
STRUCTURAL = {"per_view", "per_frame", "per_frame_index", "by_view", "by_frame", "views", "frames", "mean", "values"}


def scalar(value: Any) -> float | None:
    """A finite number from ``value`` (a number, or a dict with a value-like key), else None."""
    if isinstance(value, Mapping):
        for key in VALUE_KEYS:
            if key in value:
                return scalar(value[key])
        return None
    if isinstance(value, bool) or not isinstance(value, int | float):
        return None
    x = float(value)
    return x if math.isfinite(x) else None


def interval(value: Any) -> tuple[float, float] | None:
    """(lo, hi) from ``[lo, hi]`` or a dict with low/high keys, else None."""
    if isinstance(value, list | tuple) and len(value) == 2:
        lo, hi = scalar(value[0]), scalar(value[1])
    elif isinstance(value, Mapping):
        lo = next((scalar(value[k]) for k in LOW_KEYS if k in value), None)
        hi = next((scalar(value[k]) for k in HIGH_KEYS if k in value), None)
    else:
        return None
    return None if lo is None or hi is None else (lo, hi)


def fmt(value: Any, digits: int = 3) -> str:
    x = scalar(value)
    return DASH if x is None else f"{x:.{digits}f}"


def fmt_with_ci(entry: Mapping[str, Any], key: str, digits: int = 2) -> tuple[str, str]:
    """(value text, interval text) of ``entry[key]`` with its interval from ``entry["ci95"][key]`` (or one inside
    the value itself: ``{"value": x, "ci95": [lo, hi]}``)."""
    raw = entry.get(key)
    ci_src: Any = None
    cis = entry.get("ci95")
    if isinstance(cis, Mapping):
        ci_src = cis.get(key)
    if ci_src is None and isinstance(raw, Mapping):
        ci_src = raw.get("ci95")
    ci = interval(ci_src)
    return fmt(raw, digits), "" if ci is None else f"[{ci[0]:.{digits}f}, {ci[1]:.{digits}f}]"


def settings_points(metrics: Mapping[str, Any]) -> list[tuple[str, str, float, float, int | None]]:
    """(task, checkpoint, sr_real, sr_imag, n) of every setting with both success rates."""
    out = []
    settings = metrics.get("settings")
    if not isinstance(settings, list):
        return []
    for s in settings:
        if not isinstance(s, Mapping):
            continue
        real, imag = scalar(s.get("sr_real")), scalar(s.get("sr_imag"))
        if real is None or imag is None:
            continue
        n = s.get("n")
        out.append(
            (
                str(s.get("task", "")),
                str(s.get("checkpoint", "")),
                real,
                imag,
                n if isinstance(n, int) and not isinstance(n, bool) else None,
            )
        )
    return out


def _as_numbers(values: list[Any]) -> list[float | None] | None:
    out: list[float | None] = []
    for v in values:
        if v is None:
            out.append(None)
        elif isinstance(v, int | float) and not isinstance(v, bool):
            out.append(float(v))
        else:
            return None
    return out if any(v is not None for v in out) else None


def _walk(node: Any, path: tuple[str, ...], found: list[tuple[tuple[str, ...], list[float | None]]]) -> None:
    if isinstance(node, Mapping):
        for k, v in node.items():
            _walk(v, (*path, str(k)), found)
    elif isinstance(node, list) and node:
        if all(isinstance(x, Mapping) for x in node):  # a list of per-frame records {psnr: …, ssim: …}
            keys = {k for x in node for k in x}
            for k in sorted(keys):
                _walk([x.get(k) for x in node], (*path, str(k)), found)
            return
        numbers = _as_numbers(node)
        if numbers is not None:
            found.append((path, numbers))


def _metric_of(path: tuple[str, ...]) -> str | None:
    lowered = [p.lower() for p in path]
    return next((m for m in CURVE_METRICS if m in lowered), None)


def single_step_curves(single_step: Any) -> dict[str, dict[str, list[float | None]]]:
    """Per-frame curves in ``single_step`` as {metric: {series label: values per frame index}}.

    Any nesting is accepted — ``{view: {psnr: [...]}}``, ``{psnr: {view: [...]}}``,
    ``{per_frame: {psnr: [...]}}`` (all views pooled), lists of per-frame records: a list of numbers whose
    path names ``psnr`` or ``ssim`` is a curve, and the rest of its path (minus structural words such as
    ``per_view``) is its label.
    """
    found: list[tuple[tuple[str, ...], list[float | None]]] = []
    _walk(single_step, (), found)
    # pilworld.metrics repeats every figure per task under "tasks": drawn only when nothing else is there.
    top = [(path, v) for path, v in found if not path or path[0] != "tasks"]
    found = top if any(_metric_of(path) for path, _ in top) else found
    panels: dict[str, dict[str, list[float | None]]] = {}
    for path, values in found:
        metric = _metric_of(path)
        if metric is None:
            continue
        rest = [p for p in path if p.lower() != metric and p.lower() not in STRUCTURAL]
        label = " · ".join(LABELS.get(p, p) for p in rest) or "all views"
        panels.setdefault(metric, {})[label] = values
    return {m: panels[m] for m in CURVE_METRICS if m in panels}
