"""One model's probe figures from its per-start records: divergence, wrong-rig PSNR, OOD actions, the shuffle."""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np

from pilworld.bench.stability.rig_errors import CALIBRATION_KINDS, RigError
from pilworld.bench.stability.settings import HEAD, SHUFFLE_ROUNDS


def _mean(xs: list[float]) -> float | None:
    return float(np.mean(xs)) if xs else None


def _median(xs: list[float]) -> float | None:
    return float(np.median(xs)) if xs else None


def _divergence(pairs: list[dict[str, float]]) -> dict[str, Any]:
    """Model vs simulator separation of two futures over starts: ``pairs`` of per-start {pred, real} MSEs."""
    pred = [p["pred"] for p in pairs]
    real = [p["real"] for p in pairs]
    ratios = [a / b for a, b in zip(pred, real, strict=True) if b > 1e-9]
    return {
        "mse_pred": _mean(pred),
        "mse_real": _mean(real),
        "ratio_median": _median(ratios),
        "distinct_share": float(np.mean([a > 0.0 for a in pred])) if pred else None,
    }


def _error_row(records: list[dict[str, Any]], error: RigError, views: list[str], applies: bool) -> dict[str, Any]:
    """One wrong rig: mean PSNR per view over the starts that have it, and its change from the right rig."""
    key = f"psnr:err:{error.key}"
    have = [r for r in records if key in r] if applies else []
    per_view = {v: _mean([r[key][v] for r in have]) for v in views}
    delta = {v: _mean([r[key][v] - r["psnr:policy"][v] for r in have]) for v in views}
    return {
        **error.to_json(),
        "applies": applies,
        "psnr_head": per_view.get(HEAD),
        "delta_db": delta.get(HEAD),
        "per_view": per_view,
        "delta_per_view": delta,
        "n": len(have),
    }


def summarize_probes(
    records: list[dict[str, Any]], views: list[str], errors: Sequence[RigError], applies: Sequence[str]
) -> dict[str, Any]:
    """One model's probe figures from its per-start records; ``applies``: the keys of the errors that reach it."""
    counterfactual = []
    for alt in ("hold", "reverse"):
        row: dict[str, Any] = {"alternative": alt}
        for v in views:
            row[v] = _divergence([r[f"div:{alt}"][v] for r in records])
        counterfactual.append(row)
    baseline = {
        "psnr_head": _mean([r["psnr:policy"][HEAD] for r in records]),
        "per_view": {v: _mean([r["psnr:policy"][v] for r in records]) for v in views},
        "n": len(records),
    }
    none = {
        "kind": "none",
        "key": "none",
        "label": "the rig's calibration",
        "params": {},
        "applies": True,
        "psnr_head": baseline["psnr_head"],
        "delta_db": 0.0 if records else None,
        "per_view": baseline["per_view"],
        "delta_per_view": {v: 0.0 if records else None for v in views},
        "n": len(records),
    }
    rows = [_error_row(records, e, views, e.key in applies) for e in errors]
    ood = []
    for kind in ("policy", "fast", "jitter", "offset"):
        have = [r for r in records if f"psnr:{kind}" in r]
        ood.append(
            {
                "kind": kind,
                "psnr_head": _mean([r[f"psnr:{kind}"][HEAD] for r in have]),
                "n": len(have),
                "per_view": {v: _mean([r[f"psnr:{kind}"][v] for r in have]) for v in views},
            }
        )
    frozen = {v: _mean([r["psnr:frozen"][v] for r in records]) for v in views}
    shuffle = [r["shuffle"] for r in records if "shuffle" in r]
    per_view = {}
    for v in views:
        shuffled = [s["psnr"][v]["shuffled"] for s in shuffle]
        own = [s["psnr"][v]["own"] for s in shuffle]
        per_view[v] = {
            **_divergence([s["div"][v] for s in shuffle]),
            "psnr_shuffled": _mean(shuffled),
            "psnr_own": _mean(own),
            "gap_db": _mean([a - b for a, b in zip(own, shuffled, strict=True)]),
            "psnr_frozen": _mean([s["psnr"][v]["frozen"] for s in shuffle]),
        }
    return {
        "starts": len(records),
        "counterfactual": {"rows": counterfactual},
        "calibration": {"rows": [none] + [r for r in rows if r["kind"] in CALIBRATION_KINDS]},
        "robot_mismatch": {"baseline": baseline, "rows": [r for r in rows if r["kind"] == "robot_model"]},
        "ood_actions": {"rows": ood, "frozen_per_view": frozen},
        "action_shuffle": {
            "rounds": SHUFFLE_ROUNDS,
            "n": len(shuffle),
            "per_view": per_view,
            "deterministic_share": float(np.mean([s["same"] for s in shuffle])) if shuffle else None,
        },
    }
