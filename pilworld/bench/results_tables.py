"""Markdown tables of docs/RESULTS.md from the benches' JSON (``python -m pilworld.bench.results_tables DIR``).

``DIR`` holds ``paired-full.json``, ``speed-accuracy-full.json`` and ``stability-full.json`` as
``scripts/bench-results`` writes them (the last line of ``pilworld bench … --json``). Every number in
the tables is printed from those files, so the document can be regenerated and checked against them.
"""

from __future__ import annotations

import argparse
import json
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any


def pct(x: Any, ci: Sequence[float] | None = None) -> str:
    if x is None:
        return "—"
    s = f"{100 * float(x):.1f}"
    return f"{s} [{100 * ci[0]:.1f}, {100 * ci[1]:.1f}]" if ci else s


def num(x: Any, digits: int = 2, ci: Sequence[float] | None = None) -> str:
    if x is None:
        return "—"
    s = f"{float(x):.{digits}f}"
    return f"{s} [{ci[0]:.{digits}f}, {ci[1]:.{digits}f}]" if ci else s


def paired_tables(r: dict[str, Any]) -> str:
    out = []
    out.append("| variant | SR_real | SR_imag | \\|ΔSR\\| | HFR | Pearson | Spearman | MMRV | pairs |")
    out.append("|---|---|---|---|---|---|---|---|---|")
    for name, row in r["variants"].items():
        o = row["overall"]
        ci = o.get("ci95") or {}
        rci = o.get("ranking_ci95") or {}
        out.append(
            f"| {name}: {row['label']} | {pct(o.get('sr_real'), ci.get('sr_real'))} | "
            f"{pct(o.get('sr_imag'), ci.get('sr_imag'))} | {pct(o.get('abs_delta_sr'), ci.get('abs_delta_sr'))} | "
            f"{num(o.get('hfr'), 3, ci.get('hfr'))} | {num(o.get('pearson'), 2, rci.get('pearson'))} | "
            f"{num(o.get('spearman'), 2, rci.get('spearman'))} | {num(o.get('mmrv'), 3, rci.get('mmrv'))} | "
            f"{o.get('n_subtasks')} |"
        )
    out.append("")
    out.append("Per task (SR in %, HFR as a fraction; 95 % bootstrap intervals over subtasks):")
    out.append("")
    out.append("| variant | task | SR_real | SR_imag | \\|ΔSR\\| | HFR |")
    out.append("|---|---|---|---|---|---|")
    for name, row in r["variants"].items():
        for task, t in row["tasks"].items():
            ci = t.get("ci95") or {}
            out.append(
                f"| {name} | {task} | {pct(t.get('sr_real'))} | {pct(t.get('sr_imag'))} | "
                f"{pct(t.get('abs_delta_sr'), ci.get('abs_delta_sr'))} | {num(t.get('hfr'), 3, ci.get('hfr'))} |"
            )
    out.append("")
    out.append("Single-step image error (round 0 of every pair; pooled PSNR in dB, gain over the frozen frame):")
    out.append("")
    views = list(next(iter(r["variants"].values()))["single_step"]["per_view"] or {})
    out.append("| variant | " + " | ".join(f"{v} PSNR (gain) / SSIM" for v in views) + " |")
    out.append("|---|" + "---|" * len(views))
    for name, row in r["variants"].items():
        pv = row["single_step"]["per_view"] or {}
        cells = [
            f"{num(pv[v].get('psnr_pooled'))} ({num(pv[v].get('gain_over_frozen_pooled_db'), 2)}) / "
            f"{num(pv[v].get('ssim'), 3)}"
            if v in pv
            else "—"
            for v in views
        ]
        out.append(f"| {name} | " + " | ".join(cells) + " |")
    out.append("")
    out.append("| variant | real failures | imagined also failed | real successes | imagined also succeeded |")
    out.append("|---|---|---|---|---|")
    for name, row in r["variants"].items():
        f = row["failure_faithfulness"]
        out.append(
            f"| {name} | {f['real_failures']} | {pct(f['imagined_also_failed'])} % | {f['real_successes']} | "
            f"{pct(f['imagined_also_succeeded'])} % |"
        )
    return "\n".join(out)


def speed_accuracy_tables(r: dict[str, Any]) -> str:
    out = [
        "| point | preset | image | steps | chunk latency, ms | × real time | head PSNR | head SSIM | "
        "\\|ΔSR\\| | HFR | front |",
        "|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    for p in r["points"]:
        front = "**yes**" if p["id"] in r["front_ids"] else ""
        out.append(
            f"| {p['id']} | {p['preset']} | {p['size']} | {p['steps']} | {p['chunk_latency_ms']:.1f} | "
            f"{p['realtime_factor']:.1f} | {num(p['psnr_head'])} | {num(p['ssim_head'], 3)} | "
            f"{pct(p.get('abs_delta_sr'))} | {num(p.get('hfr'), 3)} | {front} |"
        )
    d = r["default"]
    out.append("")
    out.append(
        f"Knee: **{d['preset']} {d['size']}, {d['steps']} step(s)**, {d['chunk_latency_ms']:.1f} ms per chunk, "
        f"head PSNR {d['psnr_head']:.2f} dB (best on the front {d['best_psnr_head']:.2f}); rule: {d['rule']}."
    )
    return "\n".join(out)


def stability_tables(r: dict[str, Any]) -> str:
    h = r["horizon"]
    out = [
        "| horizon R (rounds) | " + " | ".join(str(x["rounds"]) for x in h["rows"]) + " |",
        "|---|" + "---|" * len(h["rows"]),
        "| HFR | " + " | ".join(num(x["hfr"], 3) for x in h["rows"]) + " |",
        "",
    ]
    out.append("| round | " + " | ".join(str(x["round"]) for x in h["per_round"]) + " |")
    out.append("|---|" + "---|" * len(h["per_round"]))
    out.append("| imagined vs real, head PSNR | " + " | ".join(num(x["psnr_head"], 1) for x in h["per_round"]) + " |")
    out.append(
        "| start frame vs real (frozen) | " + " | ".join(num(x["psnr_head_frozen"], 1) for x in h["per_round"]) + " |"
    )
    f = r["failure_faithfulness"]
    out += [
        "",
        f"Failure faithfulness (R = 20): of {f['real_failures']} real failures, "
        f"{pct(f['imagined_also_failed'])} % also failed imagined; of {f['real_successes']} real successes, "
        f"{pct(f['imagined_also_succeeded'])} % also succeeded imagined.",
        "",
    ]
    views = [k for k in r["counterfactual"]["rows"][0] if k != "alternative"]
    out.append("| counterfactual | " + " | ".join(f"{v}: MSE model / MSE sim (median ratio)" for v in views) + " |")
    out.append("|---|" + "---|" * len(views))
    for row in r["counterfactual"]["rows"]:
        cells = [
            f"{num(row[v]['mse_pred'], 0)} / {num(row[v]['mse_real'], 0)} ({num(row[v]['ratio_median'])})"
            for v in views
        ]
        out.append(f"| policy vs {row['alternative']} | " + " | ".join(cells) + " |")
    out += ["", "| head camera principal point shift, px | head PSNR, dB | change, dB |", "|---|---|---|"]
    for row in r["calibration"]["rows"]:
        out.append(f"| {row['shift_px']:g} | {num(row['psnr_head'])} | {num(row['delta_db'])} |")
    out += [
        "",
        "| chunk | " + " | ".join(f"{v} PSNR" for v in views) + " | starts |",
        "|---|" + "---|" * (len(views) + 1),
    ]
    for row in r["ood_actions"]["rows"]:
        out.append(f"| {row['kind']} | " + " | ".join(num(row["per_view"][v]) for v in views) + f" | {row['n']} |")
    fz = r["ood_actions"]["frozen_per_view"]
    out.append("| (start frame held, policy chunk) | " + " | ".join(num(fz[v]) for v in views) + " | |")
    out.append("")
    out.append(f"Probe chunks refused by the safety filter: {len(r.get('refused', []))}.")
    return "\n".join(out)


def main(argv: Sequence[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__)
    p.add_argument("dir", type=Path, help="folder with <bench>-<mode>.json files")
    p.add_argument("--mode", default="full", choices=["full", "quick"])
    p.add_argument(
        "--strip",
        nargs=3,
        metavar=("RUNS", "PAIR", "PNG"),
        default=None,
        help="also draw one pair's head view: the real branch, then each variant's imagined branch",
    )
    p.add_argument("--variants", default="pilworld,ctrl_world", help="variants of the strip (comma-separated)")
    args = p.parse_args(argv)
    if args.strip:
        from pilworld.bench.charts import rollout_strip

        runs, pair, png = args.strip
        print(f"strip: {rollout_strip(runs, args.variants.split(','), pair, png)}")
    for bench, fn in (
        ("paired", paired_tables),
        ("speed-accuracy", speed_accuracy_tables),
        ("stability", stability_tables),
    ):
        path = args.dir / f"{bench}-{args.mode}.json"
        print(f"### {bench} ({path})\n")
        print(_tables_of(path, fn))
        print()
    return 0


def _tables_of(path: Path, fn: Callable[[dict[str, Any]], str]) -> str:
    """The tables of one bench's JSON, or a line saying why there are none (a bench still running leaves
    its file empty; a failed one leaves its log's last line, which is not JSON)."""
    if not path.is_file():
        return f"({path} missing)"
    try:
        result = json.loads(path.read_text())
    except json.JSONDecodeError as e:
        return f"({path} is not a bench result: {e}; rerun its bench with --json)"
    return fn(result)


if __name__ == "__main__":
    raise SystemExit(main())
