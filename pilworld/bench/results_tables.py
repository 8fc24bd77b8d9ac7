"""Markdown tables of docs/RESULTS.md from the benches' JSON (``python -m pilworld.bench.results_tables DIR``).

``DIR`` holds ``paired-full.json``, ``speed-accuracy-full.json`` and ``stability-full.json`` as
``scripts/bench-results`` writes them (the last line of ``pilworld bench … --json``). Every number in
the tables is printed from those files, so the document can be regenerated and checked against them.
"""

from __future__ import annotations

import argparse
import json
from collections.abc import Callable, Mapping, Sequence
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


def share(a: dict[str, Any] | None) -> str:
    """``k/n = share [lo, hi]`` of an agreement count (Wilson interval), or — without pairs."""
    if not a or not a.get("n"):
        return "—"
    ci = a.get("ci95")
    tail = f" [{ci[0]:.2f}, {ci[1]:.2f}]" if ci else ""
    return f"{a['k']}/{a['n']} = {a['share']:.2f}{tail}"


def _row_cells(row: dict[str, Any]) -> str:
    o = row["overall"]
    ci = o.get("ci95") or {}
    rci = o.get("ranking_ci95") or {}
    agree = row.get("agreement") or {}
    return (
        f"{pct(o.get('sr_imag'), ci.get('sr_imag'))} | {pct(o.get('abs_delta_sr'), ci.get('abs_delta_sr'))} | "
        f"{num(o.get('hfr'), 3, ci.get('hfr'))} | {num(o.get('pearson'), 2, rci.get('pearson'))} | "
        f"{num(o.get('spearman'), 2, rci.get('spearman'))} | {num(o.get('mmrv'), 3, rci.get('mmrv'))} | "
        f"{share(agree.get('successes'))} | {share(agree.get('failures'))}"
    )


_HEAD = (
    "| variant | SR_imag | \\|ΔSR\\| | HFR | Pearson | Spearman | MMRV | real successes also imagined | "
    "real failures also imagined |"
)


def _comparison_cells(c: Mapping[str, Any]) -> str:
    """The cells every paired comparison prints (pilworld.bench.claims.compare plus its direction):
    Δ|ΔSR|, ΔHFR, Δ per-pair agreement with their intervals, then the three directions."""
    d, ci, v = c["difference"], c["ci95"], c["direction"]
    return (
        f"{pct(d['abs_delta_sr'], ci.get('abs_delta_sr'))} | {num(d['hfr'], 3, ci.get('hfr'))} | "
        f"{pct(d['agreement'], ci.get('agreement'))} | {v['abs_delta_sr']} · {v['hfr']} · {v['agreement']}"
    )


def paired_tables(r: dict[str, Any]) -> str:
    rows = r["variants"]
    first = next(iter(rows.values()))["overall"]
    ci0 = first.get("ci95") or {}
    out = [
        f"SR_real (shared real branches): {pct(first.get('sr_real'), ci0.get('sr_real'))} % by the image-only judge "
        f"({pct(first.get('sr_real_checker'))} % by the simulator's checker); {first.get('n_subtasks')} pairs per "
        "variant. SR, |ΔSR| in %; intervals 95 %.",
        "",
        _HEAD,
        "|---|---|---|---|---|---|---|---|---|",
    ]
    for name, row in rows.items():
        out.append(f"| {name}: {row['label']} | {_row_cells(row)} |")
    gamma = [n for n in r.get("gamma_plus_rows", []) if n in rows]
    if len(gamma) > 1:
        out += ["", "The Γ⁺ ablation (head-view single-step PSNR in dB, round 0 of every pair):", ""]
        out.append(_HEAD + " head PSNR |")
        out.append("|---|---|---|---|---|---|---|---|---|---|")
        for name in gamma:
            row = rows[name]
            head = (row["single_step"].get("per_view") or {}).get("cam_high") or {}
            out.append(f"| {name} | {_row_cells(row)} | {num(head.get('psnr_pooled'))} |")
    ladder = r.get("gamma_plus_steps") or []
    if ladder:
        out += [
            "",
            "Each Γ⁺ step against the row before it (later − earlier on the same pairs; 95 % paired bootstrap "
            "intervals; |ΔSR| and agreement in points):",
            "",
            "| step | Δ\\|ΔSR\\| (lower is better) | ΔHFR | Δ per-pair agreement | the later row is better? "
            "(\\|ΔSR\\| · HFR · agreement) |",
            "|---|---|---|---|---|",
        ]
        for c in ladder:
            out.append(f"| {c['from']} → {c['to']} | {_comparison_cells(c)} |")
    claims = r.get("claims") or []
    if claims:
        out += [
            "",
            "The paper's claims, each a paired comparison on the same pairs (better − worse; 95 % paired bootstrap "
            "intervals; |ΔSR| and agreement in points):",
            "",
            "| claim | better − worse | Δ\\|ΔSR\\| (lower is better) | ΔHFR | Δ per-pair agreement | verdict "
            "(\\|ΔSR\\| · HFR · agreement) |",
            "|---|---|---|---|---|---|",
        ]
        for c in claims:
            out.append(f"| {c['text']} | {c['better']} − {c['worse']} | {_comparison_cells(c)} |")
    out += [
        "",
        "Per task (SR in %, HFR as a fraction; 95 % bootstrap intervals over subtasks):",
        "",
        "| variant | task | SR_real | SR_imag | \\|ΔSR\\| | HFR | real successes also imagined | "
        "real failures also imagined |",
        "|---|---|---|---|---|---|---|---|",
    ]
    for name, row in rows.items():
        by_task = (row.get("agreement") or {}).get("tasks") or {}
        for task, t in row["tasks"].items():
            ci = t.get("ci95") or {}
            a = by_task.get(task) or {}
            out.append(
                f"| {name} | {task} | {pct(t.get('sr_real'))} | {pct(t.get('sr_imag'))} | "
                f"{pct(t.get('abs_delta_sr'), ci.get('abs_delta_sr'))} | {num(t.get('hfr'), 3, ci.get('hfr'))} | "
                f"{share(a.get('successes'))} | {share(a.get('failures'))} |"
            )
    out.append("")
    out.append("Single-step image error (round 0 of every pair; pooled PSNR in dB, gain over the frozen frame):")
    out.append("")
    views = list(next(iter(rows.values()))["single_step"]["per_view"] or {})
    out.append("| variant | " + " | ".join(f"{v} PSNR (gain) / SSIM" for v in views) + " |")
    out.append("|---|" + "---|" * len(views))
    for name, row in rows.items():
        pv = row["single_step"]["per_view"] or {}
        cells = [
            f"{num(pv[v].get('psnr_pooled'))} ({num(pv[v].get('gain_over_frozen_pooled_db'), 2)}) / "
            f"{num(pv[v].get('ssim'), 3)}"
            if v in pv
            else "—"
            for v in views
        ]
        out.append(f"| {name} | " + " | ".join(cells) + " |")
    return "\n".join(out)


def _sa_params(x: Any) -> str:
    return "—" if x is None else f"{float(x) / 1e6:.2f} M"


def _sa_model(p: dict[str, Any]) -> str:
    """ "v1 tiny", "v2" (v2 has no presets)."""
    family = p.get("family", "v1")
    return family if p["preset"] == family else f"{family} {p['preset']}"


def _sa_count(x: int) -> str:
    return f"{x / 1e6:+.2f} M" if abs(x) >= 10_000 else f"{x:+d}"


def _sa_signed(x: Any, digits: int = 1, scale: float = 1.0) -> str:
    return "—" if x is None else f"{scale * float(x):+.{digits}f}"


def speed_accuracy_tables(r: dict[str, Any]) -> str:
    """The sweep's points, the knee (on closed-loop accuracy) beside the shipped default, and what each step up
    in size or sampling steps buys. Latency is one whole imagined round; |ΔSR| and SR in points."""
    out = [
        "| point | family / preset | image | steps | params | round, ms | × real time | \\|ΔSR\\| | HFR | SR_imag | "
        "head PSNR | front |",
        "|---|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    for p in r["points"]:
        what = _sa_model(p)
        if p.get("skipped"):
            out.append(f"| {p['id']} | {what} | {p['size']} | — | — | {p['skipped']} | | | | | | |")
            continue
        ci = p.get("ci95") or {}
        front = "**yes**" if p["id"] in r["front_ids"] else ""
        note = " (untrained)" if p.get("untrained") else ""
        out.append(
            f"| {p['id']}{note} | {what} | {p['size']} | {p['steps'] if p.get('family') != 'v2' else '— (1 pass)'} | "
            f"{_sa_params(p.get('params'))} | {p['chunk_latency_ms']:.1f} | {p['realtime_factor']:.1f} | "
            f"{pct(p.get('abs_delta_sr'), ci.get('abs_delta_sr'))} | {num(p.get('hfr'), 3, ci.get('hfr'))} | "
            f"{pct(p.get('sr_imag'))} | {num(p.get('psnr_head'))} | {front} |"
        )
    d = r["default"]
    out.append("")
    if d.get("id") is None:
        out.append(f"Knee: none ({d.get('none', 'no closed-loop figures')}).")
    else:
        out.append(
            f"Knee: **{d['id']}** ({_sa_model(d)} {d['size']}, {_sa_params(d['params'])}), "
            f"{d['chunk_latency_ms']:.1f} ms per round, |ΔSR| {pct(d['abs_delta_sr'])}, HFR {num(d['hfr'], 3)} "
            f"(best: |ΔSR| {pct(d['best_abs_delta_sr'])} by {d['best_id']}, HFR {num(d['best_hfr'], 3)}); "
            f"rule: {d['rule']}."
        )
    shipped = r.get("shipped_default") or {}
    if shipped.get("verdict"):
        out.append(f"Shipped default ({shipped['id']}): {shipped['verdict']}.")
    single = r.get("single_step_knee") or {}
    if single.get("id"):
        out.append(f"For contrast, the single-step knee (head PSNR): {single['id']}; rule: {single['rule']}.")
    buys = [("steps", b) for b in r.get("steps_buy", [])] + [("size", b) for b in r.get("size_buy", [])]
    if buys:
        out += [
            "",
            "What each step up buys (the later point minus the earlier; |ΔSR| and SR_imag in points, latency of a "
            "whole round):",
            "",
            "| step up | from → to | params | round, ms (×) | \\|ΔSR\\| | HFR | SR_imag | head PSNR, dB |",
            "|---|---|---|---|---|---|---|---|",
        ]
        for kind, b in buys:
            what = f"{b['steps'][0]} → {b['steps'][1]} sampling steps" if kind == "steps" else b["what"]
            if b.get("skipped"):
                out.append(f"| {what} | {b['from']} → {b['to']} | {b['skipped']} | | | | | |")
                continue
            ratio = f" (×{b['latency_ratio']:.2f})" if b.get("latency_ratio") is not None else ""
            out.append(
                f"| {what} | {b['from']} → {b['to']} | {_sa_count(b['d_params'])} | "
                f"{_sa_signed(b['d_latency_ms'])}{ratio} | {_sa_signed(b['d_abs_delta_sr'], 1, 100)} | "
                f"{_sa_signed(b['d_hfr'], 3)} | {_sa_signed(b['d_sr_imag'], 1, 100)} | "
                f"{_sa_signed(b['d_psnr_head'], 2)} |"
            )
    return "\n".join(out)


def stability_tables(r: dict[str, Any]) -> str:
    models = r["models"]
    names = list(models)
    first = models[names[0]]
    hrows = first["horizon"]["rows"]
    out = [
        "| model | " + " | ".join(f"HFR at R = {x['rounds']}" for x in hrows) + " |",
        "|---|" + "---|" * len(hrows),
    ]
    for name, m in models.items():
        out.append(f"| {name} | " + " | ".join(num(x["hfr"], 3) for x in m["horizon"]["rows"]) + " |")
    per_round = first["horizon"]["per_round"]
    out += ["", "| head PSNR at the end of round | " + " | ".join(str(x["round"]) for x in per_round) + " |"]
    out.append("|---|" + "---|" * len(per_round))
    for name, m in models.items():
        out.append(f"| {name} | " + " | ".join(num(x["psnr_head"], 1) for x in m["horizon"]["per_round"]) + " |")
    out.append("| start frame held (frozen) | " + " | ".join(num(x["psnr_head_frozen"], 1) for x in per_round) + " |")
    out += [
        "",
        "| failure faithfulness (R = 20) | real failures | also failed imagined, % | real successes | "
        "also succeeded imagined, % |",
        "|---|---|---|---|---|",
    ]
    for name, m in models.items():
        f = m["failure_faithfulness"]
        out.append(
            f"| {name} | {f['real_failures']} | {pct(f['imagined_also_failed'])} | {f['real_successes']} | "
            f"{pct(f['imagined_also_succeeded'])} |"
        )
    views = [k for k in first["counterfactual"]["rows"][0] if k != "alternative"]
    out += ["", "| counterfactual | " + " | ".join(f"{v}: MSE model / MSE sim (median ratio)" for v in views) + " |"]
    out.append("|---|" + "---|" * len(views))
    for name, m in models.items():
        for row in m["counterfactual"]["rows"]:
            cells = [
                f"{num(row[v]['mse_pred'], 0)} / {num(row[v]['mse_real'], 0)} ({num(row[v]['ratio_median'])})"
                for v in views
            ]
            out.append(f"| {name}: policy vs {row['alternative']} | " + " | ".join(cells) + " |")
    wrists = views[1:]
    out += [
        "",
        "| rig given to the model (the simulator keeps the right one) | "
        + " | ".join(f"{n}: head PSNR, dB | {n}: change head / " + " / ".join(wrists) + ", dB" for n in names)
        + " |",
        "|---|" + "---|---|" * len(names),
    ]
    errors = first["calibration"]["rows"] + first["robot_mismatch"]["rows"]
    for i, row in enumerate(errors):
        cells = []
        for name in names:
            m = models[name]
            e = (m["calibration"]["rows"] + m["robot_mismatch"]["rows"])[i]
            if not e["applies"]:
                cells += ["does not reach it", ""]
                continue
            delta = e["delta_per_view"]
            cells += [num(e["psnr_head"]), " / ".join(num(delta.get(v)) for v in [views[0], *wrists])]
        out.append(f"| {row['label']} | " + " | ".join(cells) + " |")
    out += [
        "",
        "| chunk | " + " | ".join(f"{v} PSNR" for v in views) + " | starts |",
        "|---|" + "---|" * (len(views) + 1),
    ]
    for name, m in models.items():
        for row in m["ood_actions"]["rows"]:
            out.append(
                f"| {name}: {row['kind']} | " + " | ".join(num(row["per_view"][v]) for v in views) + f" | {row['n']} |"
            )
    fz = first["ood_actions"]["frozen_per_view"]
    out.append("| start frame held, policy chunk | " + " | ".join(num(fz[v]) for v in views) + " | |")
    sh0 = first["action_shuffle"]
    out += [
        "",
        f"Action shuffle: another episode's chunks transplanted onto the start, {sh0['rounds']} rounds "
        "(MSE between the own and the shuffled futures; PSNR against the simulator's same future):",
        "",
        "| model: view | MSE model / MSE sim (median ratio) | model's futures differ, % | PSNR shuffled, dB | "
        "PSNR own chunks, dB | start frame held, dB | starts | identical when imagined twice, % |",
        "|---|---|---|---|---|---|---|---|",
    ]
    for name, m in models.items():
        sh = m["action_shuffle"]
        for v in views:
            s = sh["per_view"][v]
            out.append(
                f"| {name}: {v} | {num(s['mse_pred'], 0)} / {num(s['mse_real'], 0)} ({num(s['ratio_median'])}) | "
                f"{pct(s['distinct_share'])} | {num(s['psnr_shuffled'])} | {num(s['psnr_own'])} | "
                f"{num(s['psnr_frozen'])} | {sh['n']} | {pct(sh['deterministic_share'])} |"
            )
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
    p.add_argument(
        "--variants",
        default="pilworld,v2_paper_gamma,v2_ctrl_world,v2_markers,v2_render,v2_render_prior",
        help="variants of the strip (comma-separated)",
    )
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
