"""The rungs' statistics: rates with bootstrap intervals, paired SR differences, PSNR, the judges' agreement."""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np
import torch

from pilworld.bench.wm_ladder.settings import Frames
from pilworld.paired.runner import PairedSubtask


def mean_ci(values: Sequence[float | bool | None]) -> dict[str, Any]:
    """Mean of the non-missing values, their count and a 95 % bootstrap interval."""
    from pilworld.metrics.bootstrap import bootstrap_means

    col = np.array([np.nan if v is None else float(v) for v in values], dtype=np.float64)
    ok = np.isfinite(col)
    if not ok.any():
        return {"rate": None, "n": 0, "ci95": None}
    return {
        "rate": round(float(col[ok].mean()), 4),
        "n": int(ok.sum()),
        "ci95": rounded(bootstrap_means({"x": col})["x"]),
    }


def rounded(x: Any, digits: int = 4) -> Any:
    if isinstance(x, float):
        return round(x, digits)
    if isinstance(x, list):
        return [rounded(v, digits) for v in x]
    return x


def paired_rates(columns: Mapping[str, Sequence[bool]], reference: str) -> dict[str, Any]:
    """SR per column with 95 % intervals, and each column's paired difference to ``reference``."""
    from pilworld.metrics.bootstrap import bootstrap_means

    cols = {k: np.array([float(v) for v in vals], dtype=np.float64) for k, vals in columns.items()}
    others = [k for k in cols if k != reference]
    ci = bootstrap_means(cols, differences={f"d_{k}": (k, reference) for k in others})
    return {
        "sr": {k: round(float(v.mean()), 4) for k, v in cols.items()},
        "sr_ci95": {k: rounded(ci[k]) for k in cols},
        "delta_vs_" + reference: {k: round(float(cols[k].mean() - cols[reference].mean()), 4) for k in others},
        "delta_ci95": {k: rounded(ci[f"d_{k}"]) for k in others},
        "flips": {
            k: {
                "lost": int(np.sum((cols[reference] == 1) & (cols[k] == 0))),
                "gained": int(np.sum((cols[reference] == 0) & (cols[k] == 1))),
            }
            for k in others
        },
    }


def per_task(records: Sequence[tuple[PairedSubtask, dict[str, Any]]], keys: Sequence[str]) -> dict[str, Any]:
    out: dict[str, Any] = {}
    for task in dict.fromkeys(p.subtask.task for p, _ in records):
        rows = [r for p, r in records if p.subtask.task == task]
        out[task] = {"n": len(rows), **{k: round(float(np.mean([r[k] for r in rows])), 4) for k in keys}}
    return out


def psnr(mse_value: float) -> float:
    from pilworld.world_model.metrics import psnr_from_mse

    return round(float(psnr_from_mse(torch.tensor(float(mse_value), dtype=torch.float64))), 3)


def frame_mse(a: Frames, b: Frames) -> float:
    """Mean squared error (levels²) over all frames and pixels of two [N, H, W, 3] stacks."""
    return float(np.mean((np.asarray(a, dtype=np.float64) - np.asarray(b, dtype=np.float64)) ** 2))


def judgement(verdict: Any) -> dict[str, Any]:
    return {
        "success": bool(verdict.success),
        "hallucination_frame": verdict.first_hallucination_frame,
        "reason": verdict.reason,
    }


def judge_summary(rows: Sequence[tuple[bool, dict[str, Any]]]) -> dict[str, Any]:
    """Agreement of the image-only judge with the checker, its confusion matrix and the false-positive rate."""
    confusion = {"tp": 0, "fp": 0, "fn": 0, "tn": 0}
    categories: dict[str, int] = {}
    for truth, j in rows:
        said = bool(j["success"])
        confusion[("tp" if truth else "fp") if said else ("fn" if truth else "tn")] += 1
        if j["hallucination_frame"] is not None:
            cat = str(j["reason"]).split("hallucination: ", 1)[-1].split(":", 1)[0]
            categories[cat] = categories.get(cat, 0) + 1
    agree = mean_ci([bool(j["success"]) == truth for truth, j in rows])
    fp = mean_ci([j["hallucination_frame"] is not None for _, j in rows])
    return {
        "n": len(rows),
        "agreement": agree["rate"],
        "agreement_ci95": agree["ci95"],
        "sr_judge": round(float(np.mean([bool(j["success"]) for _, j in rows])), 4) if rows else None,
        "confusion": confusion,
        "hallucination_fp_rate": fp["rate"],
        "hallucination_fp_ci95": fp["ci95"],
        "fp_categories": categories,
    }


def learned_judgement(verdict: Any) -> dict[str, Any]:
    """A learned judge's verdict: success True / False, or None where it abstained."""
    return {"success": verdict.success, "reason": verdict.reason}


def learned_summary(
    rows: Sequence[tuple[bool, dict[str, Any]]], plain: Sequence[dict[str, Any]] | None = None
) -> dict[str, Any]:
    """Agreement of a learned judge with the checker on the episodes it judged (abstentions counted apart),
    and, given the same episodes' ``plain`` verdicts, the drop from them on the episodes judged in both."""
    judged = [(t, j) for t, j in rows if j["success"] is not None]
    agree = mean_ci([bool(j["success"]) == t for t, j in judged])
    out: dict[str, Any] = {
        "n": len(rows),
        "judged": len(judged),
        "abstained": len(rows) - len(judged),
        "agreement": agree["rate"],
        "agreement_ci95": agree["ci95"],
    }
    if plain is not None:
        both = [
            (t, j, p)
            for (t, j), p in zip(rows, plain, strict=True)
            if j["success"] is not None and p["success"] is not None
        ]
        if both:
            here = float(np.mean([bool(j["success"]) == t for t, j, _ in both]))
            base = float(np.mean([bool(p["success"]) == t for t, _, p in both]))
            out["both_judged"] = len(both)
            out["agreement_drop_points"] = round(100 * (base - here), 2)
            out["verdicts_changed"] = sum(bool(j["success"]) != bool(p["success"]) for _, j, p in both)
    return out
