"""``bench speed-accuracy``'s verdicts: the front, the knee, the shipped default, what each step up buys.

The rules are :mod:`pilworld.bench.speed_accuracy`'s docstring's "Front and knee"; this module only reads the
sweep's points (dicts with ``id``, ``params``, ``chunk_latency_ms``, ``abs_delta_sr``, ``hfr``, …).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

SHIPPED = "v2_shipped"
# The knee's tolerances. SR over N pairs moves in steps of 1/N, so two points one pair apart are not told apart
# by the protocol (at 18 pairs, the 95 % interval of |ΔSR| is ±10 points or more); 5 points is the project's
# |ΔSR| target, the tolerance never goes below it. HFR is a per-frame rate, steadier than SR: 0.05 is about its
# 95 % half-width at 18 pairs (v2 on 300 pairs: ±0.018, ×√(300/18) ≈ 4), and 0.85 → 0.90 is the target's scale.
KNEE_ABS_DSR_FLOOR = 0.05
KNEE_HFR = 0.05
KNEE_DB = 0.25  # the single-step knee (for contrast): head-view PSNR within this of the best
EPS = 1e-9  # float slack of the tolerance comparisons (1/18 + a difference of pair counts)
# The size steps of size_buy: (from model, to model, what). v1 models compare at 1 step.
SIZE_STEPS: tuple[tuple[str, str, str], ...] = (
    ("tiny_32", "tiny_64", "v1 tiny: image 32x32 -> 64x64"),
    ("tiny_64", "small_128", "v1: tiny 64x64 -> small 128x128 (preset and image)"),
    ("small_128", "base_128", "v1: small -> base preset (base untrained: latency only)"),
    ("v2_w8", SHIPPED, "v2: U-Net width 8 -> 16"),
    (SHIPPED, "v2_w32", "v2: U-Net width 16 -> 32"),
    (SHIPPED, "v2_work64", "v2: U-Net work size 32x32 -> 64x64"),
    ("small_128", SHIPPED, "v1 small -> v2 (another model, not a size step)"),
)
CLOSED_LOOP_OBJECTIVES: tuple[tuple[str, int], ...] = (("chunk_latency_ms", -1), ("abs_delta_sr", -1), ("hfr", 1))
SINGLE_STEP_OBJECTIVES: tuple[tuple[str, int], ...] = (("chunk_latency_ms", -1), ("psnr_head", 1))


def _scored(p: Mapping[str, Any], keys: Sequence[str]) -> bool:
    return not p.get("untrained") and not p.get("skipped") and all(p.get(k) is not None for k in keys)


def pareto_front(
    points: Sequence[Mapping[str, Any]], objectives: Sequence[tuple[str, int]] = CLOSED_LOOP_OBJECTIVES
) -> list[str]:
    """Ids of the points not dominated on ``objectives`` ((key, +1 higher is better / −1 lower is better)): no
    other point is at least as good on every one and better on one. Untrained, skipped and unmeasured points
    take no part. Sorted by latency."""
    keys = [k for k, _ in objectives]
    scored = [p for p in points if _scored(p, keys)]

    def beats(q: Mapping[str, Any], p: Mapping[str, Any]) -> bool:
        no_worse = all(s * q[k] >= s * p[k] for k, s in objectives)
        return no_worse and any(s * q[k] > s * p[k] for k, s in objectives)

    front = [p for p in scored if not any(q is not p and beats(q, p) for q in scored)]
    return [p["id"] for p in sorted(front, key=lambda p: (p["chunk_latency_ms"], p["id"]))]


def knee_tolerances(pairs: int) -> dict[str, float]:
    """How far from the best a point may be and still "reach the accuracy" on a protocol of ``pairs`` pairs."""
    if pairs < 1:
        raise ValueError(f"pairs: expected at least 1, got {pairs}")
    return {"abs_delta_sr": round(max(KNEE_ABS_DSR_FLOOR, 1.0 / pairs), 4), "hfr": KNEE_HFR}


def choose_knee(points: Sequence[Mapping[str, Any]], front: Sequence[str], *, pairs: int) -> dict[str, Any]:
    """The smallest model that reaches the closed-loop accuracy (see the module docstring)."""
    scored = [p for p in points if _scored(p, ("chunk_latency_ms", "abs_delta_sr", "hfr"))]
    if not scored:
        raise ValueError(
            "speed-accuracy: no point has a closed-loop accuracy (|ΔSR| and HFR of a trained model); "
            "nothing to choose the knee from"
        )
    tol = knee_tolerances(pairs)
    best = min(scored, key=lambda p: (p["abs_delta_sr"], -p["hfr"], p["chunk_latency_ms"], p["id"]))
    best_hfr = max(p["hfr"] for p in scored)
    near_dsr = [p for p in scored if p["abs_delta_sr"] <= best["abs_delta_sr"] + tol["abs_delta_sr"] + EPS]
    reach = [p for p in near_dsr if p["hfr"] >= best_hfr - tol["hfr"] - EPS]
    rule = (
        f"fewest parameters (ties: fastest) among the real-time points whose closed-loop |ΔSR| is within "
        f"{tol['abs_delta_sr']:.3f} of the best ({100 * best['abs_delta_sr']:.1f} points, {best['id']}) and whose "
        f"HFR is within {tol['hfr']:.2f} of the best ({best_hfr:.3f})"
    )
    if not reach:  # the best |ΔSR| and the best HFR are far apart: |ΔSR|, the headline figure, decides
        reach = near_dsr
        rule += "; no point reaches both, so the |ΔSR| tolerance alone"
    realtime = [p for p in reach if p["realtime_factor"] >= 1.0]
    if realtime:
        pick = min(realtime, key=lambda p: (p["params"], p["chunk_latency_ms"], p["id"]))
    else:
        pick = min(reach, key=lambda p: (p["chunk_latency_ms"], p["id"]))
        rule += "; none of them keeps real time, so the fastest of them"
    return {
        "id": pick["id"],
        "family": pick.get("family"),
        "preset": pick["preset"],
        "size": pick["size"],
        "steps": pick["steps"],
        "params": pick["params"],
        "chunk_latency_ms": pick["chunk_latency_ms"],
        "realtime_factor": pick["realtime_factor"],
        "abs_delta_sr": pick["abs_delta_sr"],
        "hfr": pick["hfr"],
        "sr_imag": pick.get("sr_imag"),
        "psnr_head": pick.get("psnr_head"),
        "on_front": pick["id"] in front,
        "best_id": best["id"],
        "best_abs_delta_sr": best["abs_delta_sr"],
        "best_hfr": best_hfr,
        "tolerances": tol,
        "pairs": pairs,
        "reaching": sorted(p["id"] for p in reach),
        "rule": rule,
    }


def choose_single_step_default(points: Sequence[Mapping[str, Any]], front: Sequence[str]) -> dict[str, Any]:
    """The old knee, on single-step accuracy: the fastest real-time point of the (latency, head PSNR) front
    within :data:`KNEE_DB` of the best head-view PSNR (the fastest front point when none keeps real time)."""
    on_front = [p for p in points if p["id"] in front and _scored(p, ("psnr_head",))]
    if not on_front:
        raise ValueError("speed-accuracy: no point has a single-step accuracy (nothing to choose from)")
    best = max(p["psnr_head"] for p in on_front)
    good = [p for p in on_front if p["psnr_head"] >= best - KNEE_DB and p["realtime_factor"] >= 1.0]
    pick = min(good or on_front, key=lambda p: p["chunk_latency_ms"])
    return {
        "id": pick["id"],
        "preset": pick["preset"],
        "size": pick["size"],
        "steps": pick["steps"],
        "chunk_latency_ms": pick["chunk_latency_ms"],
        "psnr_head": pick["psnr_head"],
        "best_psnr_head": best,
        "front_ids": list(front),
        "rule": f"fastest real-time point of the (latency, head PSNR) front within {KNEE_DB} dB of the best",
    }


def _delta(a: Mapping[str, Any], b: Mapping[str, Any], key: str) -> float | None:
    x, y = a.get(key), b.get(key)
    return None if x is None or y is None else round(float(y) - float(x), 4)


def _change(a: Mapping[str, Any], b: Mapping[str, Any]) -> dict[str, Any]:
    """What going from point ``a`` to point ``b`` changes (b − a; latency also as a ratio)."""
    ratio = b["chunk_latency_ms"] / a["chunk_latency_ms"] if a["chunk_latency_ms"] else None
    return {
        "d_params": b["params"] - a["params"],
        "d_latency_ms": _delta(a, b, "chunk_latency_ms"),
        "latency_ratio": None if ratio is None else round(ratio, 3),
        "d_abs_delta_sr": _delta(a, b, "abs_delta_sr"),
        "d_hfr": _delta(a, b, "hfr"),
        "d_sr_imag": _delta(a, b, "sr_imag"),
        "d_psnr_head": _delta(a, b, "psnr_head"),
    }


def steps_buy(points: Sequence[Mapping[str, Any]]) -> list[dict[str, Any]]:
    """Per v1 model, what each step count above its fewest changes against the fewest (usually 1 step)."""
    by_model: dict[str, list[Mapping[str, Any]]] = {}
    for p in points:
        if p.get("family") == "v1" and not p.get("skipped"):
            by_model.setdefault(p["model"], []).append(p)
    out = []
    for model, pts in by_model.items():
        pts = sorted(pts, key=lambda p: p["steps"])
        for p in pts[1:]:
            out.append({"model": model, "from": pts[0]["id"], "to": p["id"], "steps": [pts[0]["steps"], p["steps"]]})
            out[-1].update(_change(pts[0], p))
    return out


def size_buy(points: Sequence[Mapping[str, Any]]) -> list[dict[str, Any]]:
    """What each size step of :data:`SIZE_STEPS` changes (v1 models at their fewest steps); a step to or from a
    skipped model says so; one whose models are not in the sweep is left out."""
    first: dict[str, Mapping[str, Any]] = {}
    for p in sorted(points, key=lambda p: p.get("steps") or 0):
        first.setdefault(p["model"], p)
    out: list[dict[str, Any]] = []
    for a, b, what in SIZE_STEPS:
        if a not in first or b not in first:
            continue
        pa, pb = first[a], first[b]
        row: dict[str, Any] = {"from": pa["id"], "to": pb["id"], "what": what}
        skipped = [p["skipped"] for p in (pa, pb) if p.get("skipped")]
        if skipped:
            row["skipped"] = "; ".join(f"{p['id']} {p['skipped']}" for p in (pa, pb) if p.get("skipped"))
        else:
            row.update(_change(pa, pb))
        out.append(row)
    return out


def shipped_verdict(points: Sequence[Mapping[str, Any]], knee: Mapping[str, Any]) -> dict[str, Any]:
    """The shipped default (``v2_shipped``) against the knee: does it sit there, else what it should become."""
    shipped = next((p for p in points if p["id"] == SHIPPED and not p.get("skipped")), None)
    out: dict[str, Any] = {"id": SHIPPED, "agrees": knee["id"] == SHIPPED}
    if shipped is not None:
        keys = ("family", "params", "chunk_latency_ms", "realtime_factor", "abs_delta_sr", "hfr", "sr_imag")
        out |= {k: shipped.get(k) for k in keys} | {"psnr_head": shipped.get("psnr_head")}
    if out["agrees"]:
        out["verdict"] = "the shipped default (v2) is the knee: the smallest model that reaches the accuracy"
    elif shipped is None:
        out["verdict"] = f"v2_shipped is not in this sweep; the knee is {knee['id']}"
    else:
        out["verdict"] = (
            f"the knee is {knee['id']} ({knee['preset']} {knee['size']}, {knee['steps']} step(s), "
            f"{knee['params']:,} parameters), not the shipped v2: the default should become {knee['id']}"
        )
    return out
