"""The benchmark charts of docs/RESULTS.md (matplotlib, Agg, PNG files).

One function per chart; each takes the bench's JSON (or a part of it) and a path, so a chart can be
redrawn from a saved result without rerunning anything.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

from pilworld.report.charts import SERIES_COLORS, _png


def _plt() -> Any:
    from pilworld.report.charts import _pyplot

    return _pyplot()


def _write(fig: Any, path: str | Path) -> Path:
    p = Path(path)
    p.parent.mkdir(parents=True, exist_ok=True)
    p.write_bytes(_png(fig))
    return p


def _value(x: Any) -> float:
    return float("nan") if x is None else float(x)


def paired_table_chart(
    variants: Mapping[str, Mapping[str, Any]], targets: Mapping[str, float], path: str | Path
) -> Path:
    """|ΔSR| and HFR per variant (bars with 95 % intervals) beside the targets; SR_imag vs SR_real per setting."""
    plt = _plt()
    fig, (ax1, ax2) = plt.subplots(1, 2, figsize=(11.5, 4.4), gridspec_kw={"width_ratios": [1.4, 1]})
    names = list(variants)
    x = range(len(names))
    width = 0.38
    for j, (key, label) in enumerate((("abs_delta_sr", "|ΔSR| (lower is better)"), ("hfr", "HFR (higher is better)"))):
        vals, lo, hi = [], [], []
        for n in names:
            o = variants[n]["overall"]
            v = _value(o.get(key))
            ci = (o.get("ci95") or {}).get(key)
            vals.append(v)
            lo.append(v - ci[0] if ci else 0.0)
            hi.append(ci[1] - v if ci else 0.0)
        pos = [i + (j - 0.5) * width for i in x]
        ax1.bar(pos, vals, width, yerr=[lo, hi], capsize=3, color=SERIES_COLORS[j], label=label)
        ax1.axhline(targets[key], color=SERIES_COLORS[j], linestyle=":", linewidth=1)
    ax1.set_xticks(list(x), names, rotation=20, ha="right", fontsize=8)
    ax1.set_ylim(0, 1.05)
    ax1.set_title("per variant (dotted: our targets)", fontsize=9)
    ax1.legend(fontsize=8, loc="upper left")
    ax2.plot([0, 1], [0, 1], linestyle="--", color="#888888", linewidth=1, label="y = x")
    for k, n in enumerate(names):
        pts = [(s["sr_real"], s["sr_imag"]) for s in variants[n]["settings"] if s["sr_real"] is not None]
        if not pts:
            continue
        ax2.scatter(
            [p[0] for p in pts],
            [p[1] for p in pts],
            s=16,
            alpha=0.75,
            color=SERIES_COLORS[k % len(SERIES_COLORS)],
            label=n,
        )
    ax2.set_xlabel("SR_real per task × checkpoint")
    ax2.set_ylabel("SR_imag")
    ax2.set_xlim(-0.03, 1.03)
    ax2.set_ylim(-0.03, 1.03)
    ax2.legend(fontsize=7, loc="upper left")
    fig.tight_layout()
    return _write(fig, path)


def speed_accuracy_chart(points: Sequence[Mapping[str, Any]], front: Sequence[str], path: str | Path) -> Path:
    """Chunk latency (log x) against single-step head-view PSNR and against |ΔSR|; the Pareto front joined."""
    plt = _plt()
    fig, axes = plt.subplots(1, 2, figsize=(11.5, 4.4))
    groups: dict[str, list[Mapping[str, Any]]] = {}
    for p in points:
        groups.setdefault(f"{p['preset']} {p['size']}", []).append(p)
    for ax, key, label in (
        (axes[0], "psnr_head", "single-step head-view PSNR, dB (higher is better)"),
        (axes[1], "abs_delta_sr", "|ΔSR| in closed loop (lower is better)"),
    ):
        for k, (g, pts) in enumerate(sorted(groups.items())):
            xs = [p["chunk_latency_ms"] for p in pts if p.get(key) is not None]
            ys = [p[key] for p in pts if p.get(key) is not None]
            if not xs:
                continue
            ax.scatter(xs, ys, color=SERIES_COLORS[k % len(SERIES_COLORS)], label=g, s=22)
            for p in pts:
                if p.get(key) is not None:
                    ax.annotate(
                        str(p["steps"]),
                        (p["chunk_latency_ms"], p[key]),
                        fontsize=7,
                        xytext=(3, 3),
                        textcoords="offset points",
                    )
        on_front = sorted(
            (p for p in points if p["id"] in front and p.get(key) is not None), key=lambda p: p["chunk_latency_ms"]
        )
        if key == "psnr_head" and on_front:
            ax.plot(
                [p["chunk_latency_ms"] for p in on_front],
                [p[key] for p in on_front],
                color="#444444",
                linewidth=1,
                linestyle="--",
                label="Pareto front",
            )
        if key == "abs_delta_sr":
            ax.set_ylim(-0.02, 1.02)  # its whole range: one subtask more or less must not look like a trend
        ax.set_xscale("log")
        ax.set_xlabel("chunk latency, ms (log; labels: sampling steps)")
        ax.set_ylabel(label)
        if ax.get_legend_handles_labels()[0]:
            ax.legend(fontsize=7)
        else:
            ax.text(0.5, 0.5, "not measured (closed loop skipped)", ha="center", transform=ax.transAxes, fontsize=8)
    fig.tight_layout()
    return _write(fig, path)


def stability_chart(result: Mapping[str, Any], path: str | Path) -> Path:
    """Four panels: HFR and per-round error vs horizon, calibration perturbation, OOD actions."""
    plt = _plt()
    fig, axes = plt.subplots(1, 4, figsize=(15, 3.8))
    hz = result.get("horizon") or {}
    rows = hz.get("rows") or []
    if rows:
        axes[0].plot([r["rounds"] for r in rows], [_value(r["hfr"]) for r in rows], marker="o")
        axes[0].set_xlabel("horizon R (rounds)")
        axes[0].set_ylabel("HFR")
        axes[0].set_ylim(0, 1.05)
        axes[0].set_title("HFR vs horizon", fontsize=9)
    per_round = hz.get("per_round") or []
    if per_round:
        axes[1].plot(
            [r["round"] for r in per_round],
            [_value(r["psnr_head"]) for r in per_round],
            marker=".",
            label="imagined vs real",
        )
        axes[1].plot(
            [r["round"] for r in per_round],
            [_value(r.get("psnr_head_frozen")) for r in per_round],
            linestyle="--",
            label="start frame vs real",
        )
        axes[1].set_xlabel("round")
        axes[1].set_ylabel("head-view PSNR, dB")
        axes[1].legend(fontsize=7)
        axes[1].set_title("error per round", fontsize=9)
    cal = (result.get("calibration") or {}).get("rows") or []
    if cal:
        axes[2].plot([r["shift_px"] for r in cal], [_value(r["psnr_head"]) for r in cal], marker="o")
        axes[2].set_xlabel("head camera principal point shift, px")
        axes[2].set_ylabel("head-view PSNR, dB")
        axes[2].set_title("calibration perturbed", fontsize=9)
    ood = (result.get("ood_actions") or {}).get("rows") or []
    if ood:
        axes[3].bar([r["kind"] for r in ood], [_value(r["psnr_head"]) for r in ood], color=SERIES_COLORS[2])
        axes[3].tick_params(axis="x", labelrotation=20, labelsize=7)
        axes[3].set_ylabel("head-view PSNR, dB")
        axes[3].set_title("out-of-distribution actions", fontsize=9)
    fig.tight_layout()
    return _write(fig, path)


def rollout_strip(
    runs: str | Path, variants: Sequence[str], pair: str, path: str | Path, view: str = "cam_high"
) -> Path:
    """Frames 0, 8, 15, 30, 45 and the last of one pair's ``view``: the real branch, then each variant's imagined."""
    import json

    import numpy as np
    from PIL import Image

    from pilworld.data.reader import EpisodeStore

    rows = []
    for k, name in enumerate(variants):
        store = EpisodeStore(Path(runs) / name)
        index = {(json.loads(r["extra"] or "{}").get("pair"), r["origin"]): i for i, r in enumerate(store.episodes)}
        for origin in ("real", "imagined") if k == 0 else ("imagined",):
            if (pair, origin) not in index:
                raise ValueError(f"rollout_strip: {Path(runs) / name} has no {origin} branch of {pair}")
            frames = store.frames(index[(pair, origin)], view)
            picks = [0, 8, 15, 30, 45, len(frames) - 1]
            rows.append(np.concatenate([frames[min(i, len(frames) - 1)] for i in picks], axis=1))
    p = Path(path)
    p.parent.mkdir(parents=True, exist_ok=True)
    Image.fromarray(np.concatenate(rows, axis=0)).save(p)
    return p
