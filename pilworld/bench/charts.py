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


def speed_accuracy_chart(
    points: Sequence[Mapping[str, Any]],
    front: Sequence[str],
    path: str | Path,
    *,
    knee: str | None = None,
    shipped: str | None = "v2_shipped",
) -> Path:
    """Whole-round chunk latency (log x) against closed-loop |ΔSR| and HFR, and single-step head PSNR (small).

    Each model its colour, each family its marker (v1 ● labelled with its sampling steps, v2 ■); the closed-loop
    front (``front``) joined; the knee (``knee``) ringed and the shipped default (``shipped``) crossed.
    Untrained and skipped points have no accuracy and are not drawn.
    """
    from matplotlib.ticker import NullFormatter

    plt = _plt()
    fig, axes = plt.subplots(1, 3, figsize=(15, 4.6), gridspec_kw={"width_ratios": [1, 1, 0.75]})
    drawn = [p for p in points if not p.get("skipped") and not p.get("untrained") and p.get("chunk_latency_ms")]
    models = list(dict.fromkeys(str(p.get("model", p["id"])) for p in drawn))
    colour = {m: SERIES_COLORS[k % len(SERIES_COLORS)] for k, m in enumerate(models)}
    marker = {"v1": "o", "v2": "s"}
    for ax, key, label in (
        (axes[0], "abs_delta_sr", "closed-loop |ΔSR| (lower is better)"),
        (axes[1], "hfr", "closed-loop HFR (higher is better)"),
        (axes[2], "psnr_head", "single-step head PSNR, dB (secondary)"),
    ):
        have = [p for p in drawn if p.get(key) is not None]
        for m in models:
            pts = [p for p in have if str(p.get("model", p["id"])) == m]
            if not pts:
                continue
            family = str(pts[0].get("family", "v1"))
            ax.scatter(
                [p["chunk_latency_ms"] for p in pts],
                [p[key] for p in pts],
                color=colour[m],
                marker=marker.get(family, "^"),
                s=26,
                label=f"{m} ({family})",
            )
            for p in pts:
                ax.annotate(
                    str(p["steps"]) if family == "v1" else p["id"],
                    (p["chunk_latency_ms"], p[key]),
                    fontsize=6,
                    xytext=(3, 3),
                    textcoords="offset points",
                )
        if key != "psnr_head":
            on_front = sorted((p for p in have if p["id"] in front), key=lambda p: p["chunk_latency_ms"])
            if on_front:
                ax.plot(
                    [p["chunk_latency_ms"] for p in on_front],
                    [p[key] for p in on_front],
                    color="#444444",
                    linewidth=1,
                    linestyle="--",
                    label="front (latency, |ΔSR|, HFR)",
                )
            ax.set_ylim(-0.02, 1.02)  # the whole range: one subtask more or less must not look like a trend
        for pid, what, style in (
            (knee, "knee", {"s": 170, "facecolors": "none", "edgecolors": "black", "linewidths": 1.5}),
            (shipped, "shipped default", {"s": 90, "marker": "x", "color": "black", "linewidths": 1.2}),
        ):
            for p in [q for q in have if pid is not None and q["id"] == pid][:1]:
                ax.scatter([p["chunk_latency_ms"]], [p[key]], label=f"{what}: {pid}", zorder=5, **style)
        ax.set_xscale("log")
        ax.xaxis.set_minor_formatter(NullFormatter())  # the 2×10², 3×10², … labels overlap
        ax.set_xlabel("one imagined round, ms (log; labels: sampling steps)")
        ax.set_ylabel(label)
        if have:
            ax.legend(fontsize=6)
        else:
            ax.text(0.5, 0.5, "not measured", ha="center", transform=ax.transAxes, fontsize=8)
    fig.tight_layout()
    return _write(fig, path)


def stability_chart(result: Mapping[str, Any], path: str | Path) -> Path:
    """Per model: HFR vs horizon, per-round head error, the change of PSNR with each wrong rig (head view and
    wrist views), OOD actions, and the action shuffle's divergence ratio per view."""
    plt = _plt()
    models: Mapping[str, Any] = result.get("models") or {}
    names = list(models)
    colour = {n: SERIES_COLORS[k % len(SERIES_COLORS)] for k, n in enumerate(names)}
    width = 0.8 / max(len(names), 1)
    fig, axes = plt.subplots(2, 3, figsize=(16, 8.4))
    ax = axes[0, 0]
    for n in names:
        rows = (models[n].get("horizon") or {}).get("rows") or []
        ax.plot([r["rounds"] for r in rows], [_value(r["hfr"]) for r in rows], marker="o", color=colour[n], label=n)
    ax.set_xlabel("horizon R (rounds)")
    ax.set_ylabel("HFR")
    ax.set_ylim(0, 1.05)
    ax.set_title("HFR vs horizon", fontsize=9)
    ax.legend(fontsize=7)
    ax = axes[0, 1]
    for k, n in enumerate(names):
        per_round = (models[n].get("horizon") or {}).get("per_round") or []
        xs = [r["round"] for r in per_round]
        ax.plot(xs, [_value(r["psnr_head"]) for r in per_round], marker=".", color=colour[n], label=n)
        if k == 0 and per_round:  # the real branches are shared: one frozen curve
            ax.plot(
                xs,
                [_value(r.get("psnr_head_frozen")) for r in per_round],
                linestyle="--",
                color="#888888",
                label="start frame held",
            )
    ax.set_xlabel("round")
    ax.set_ylabel("head-view PSNR vs real, dB")
    ax.set_title("error per round", fontsize=9)
    ax.legend(fontsize=7)
    for ax, which, title in (
        (axes[0, 2], "head", "wrong rig given: change of head-view PSNR, dB"),
        (axes[1, 0], "wrists", "wrong rig given: change of wrist-view PSNR (mean), dB"),
    ):
        labels: list[str] = []
        for k, n in enumerate(names):
            m = models[n]
            rows = [*(m.get("calibration") or {}).get("rows", [])[1:], *(m.get("robot_mismatch") or {}).get("rows", [])]
            labels = labels or [r["label"] for r in rows]
            vals = []
            for r in rows:
                d = r.get("delta_per_view") or {}
                wrist = [_value(v) for view, v in d.items() if view != "cam_high"]
                vals.append(
                    _value(r.get("delta_db")) if which == "head" else (sum(wrist) / len(wrist) if wrist else 0.0)
                )
            ys = [i + (k - (len(names) - 1) / 2) * width for i in range(len(rows))]
            ax.barh(ys, vals, width, color=colour[n], label=n)
        ax.set_yticks(range(len(labels)), labels, fontsize=7)
        ax.invert_yaxis()
        ax.axvline(0.0, color="#444444", linewidth=0.8)
        ax.set_title(title, fontsize=9)
        ax.legend(fontsize=7)
    ax = axes[1, 1]
    kinds: list[str] = []
    heights: list[float] = []
    for k, n in enumerate(names):
        ood = (models[n].get("ood_actions") or {}).get("rows") or []
        kinds = kinds or [r["kind"] for r in ood]
        xs = [i + (k - (len(names) - 1) / 2) * width for i in range(len(ood))]
        ys = [_value(r["psnr_head"]) for r in ood]
        heights += [y for y in ys if y == y]  # not NaN
        ax.bar(xs, ys, width, color=colour[n], label=n)
    if heights:  # from a little below the lowest bar: the differences are a few dB
        ax.set_ylim(max(0.0, min(heights) - 3.0), max(heights) + 1.0)
    ax.set_xticks(range(len(kinds)), kinds, fontsize=8)
    ax.set_ylabel("head-view PSNR, dB")
    ax.set_title("out-of-distribution actions", fontsize=9)
    ax.legend(fontsize=7)
    ax = axes[1, 2]
    views: list[str] = []
    for k, n in enumerate(names):
        per_view = (models[n].get("action_shuffle") or {}).get("per_view") or {}
        views = views or list(per_view)
        xs = [i + (k - (len(names) - 1) / 2) * width for i in range(len(per_view))]
        ax.bar(xs, [_value(s.get("ratio_median")) for s in per_view.values()], width, color=colour[n], label=n)
    ax.axhline(1.0, color="#444444", linestyle=":", linewidth=1)
    ax.set_xticks(range(len(views)), views, fontsize=8)
    ax.set_ylabel("MSE(own, shuffled): model / simulator")
    ax.set_title("action shuffle: a different future? (1 = as different as reality)", fontsize=9)
    ax.legend(fontsize=7)
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
