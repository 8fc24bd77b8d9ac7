"""``pilworld bench paired``: the paper's table on the simulated rig — v2 and its equal-budget variants.

For every variant of :data:`FULL_VARIANTS` (the shipped world model v2 and v2's recipe with one switch each:
the paper-faithful marker Γ, the Ctrl-World-style action tokens, the Γ⁺ ablations, no history, success-only
data, + action tokens; weights in ``weights/bench/v2_*``) the same pairs run in closed loop
(:func:`~pilworld.bench.variants.evaluate_variants`; the real branches once, copied into every variant's run),
are judged by the image-only judge, and give per task SR_real, SR_imag, |ΔSR| and HFR, and across
task × checkpoint settings Pearson, Spearman and MMRV — all with bootstrap intervals — plus per-pair agreement
(real successes also imagined, real failures also imagined; Wilson intervals), single-step PSNR / SSIM per
view from each pair's first round, and the paper's claims as paired comparisons (:mod:`pilworld.bench.claims`).

``--quick`` (≤ 5 minutes on a 2-core CPU): 3 tasks × 2 checkpoints × 3 subtasks, :data:`QUICK_VARIANTS`. The
full protocol: 3 tasks × 5 checkpoints × 8 subtasks = 120 pairs per variant (docs/RESULTS.md; ``--subtasks 20``
gives the 300 pairs of the v2 release figures). Layouts come
from seed 6,000,000 on (reserved for this benchmark; training used 0–19). v1 and its baselines of 2026-11-22
run by name (``--variants pilworld_v1,ctrl_world,pilworld_3500,no_history,success_only``).
"""

from __future__ import annotations

import argparse
import time
from collections.abc import Sequence
from dataclasses import replace
from pathlib import Path
from typing import Any

from pilworld.bench.claims import Verdicts, agreement, paper_claims, steps
from pilworld.bench.common import machine_info
from pilworld.bench.flags import add_json, add_rig, run_folder
from pilworld.bench.output import Column, emit, num, pct, table
from pilworld.bench.variants import ModelVariant, PairedProtocol, evaluate_variants, standard_variants, v2_variants
from pilworld.options.bounds import at_least_one
from pilworld.options.parse import parse_list

QUICK_CHECKPOINTS = ("scripted_step_01k", "scripted_step_30k")
QUICK_SUBTASKS = 3
# The table of docs/RESULTS.md ("What is compared"): the shipped v2 and its equal-budget variants (v2's recipe,
# one switch each). v1 and its 2026-11-22 baselines stay selectable by name (``--variants pilworld_v1,...``).
FULL_VARIANTS = (
    "pilworld",
    "v2_paper_gamma",
    "v2_ctrl_world",
    "v2_markers",
    "v2_render",
    "v2_render_prior",
    "v2_no_history",
    "v2_success_only",
    "v2_tokens",
)
QUICK_VARIANTS = ("pilworld", "v2_paper_gamma", "v2_ctrl_world")
# The Γ⁺ ablation rows, from the paper's markers to the shipped render + prior + paste.
GAMMA_PLUS_ROWS = ("v2_markers", "v2_render", "v2_render_prior", "pilworld")
# 120 pairs per variant, so that the full set (scripts/bench-results) stays within 90 minutes on a 2-core CPU:
# each variant's imagined branch, judging and single-step metrics cost ~12 core-minutes at 150 pairs (two
# variants run side by side; the real branches run once), and nine variants at 150 pairs with the other two
# benches came to ~100 minutes on idle cores. ``--subtasks 10`` gives the 150 pairs of 2026-12-05's first table.
FULL_SUBTASKS = 8
# Our targets and the paper's figures (docs/RESULTS.md; paper Table 1, average over tasks).
TARGETS = {"abs_delta_sr": 0.05, "hfr": 0.85, "pearson": 0.95}
PAPER = {"abs_delta_sr": 0.120, "hfr": 0.701, "pearson": 0.94}
OVERALL_KEYS = (
    "sr_real",
    "sr_imag",
    "abs_delta_sr",
    "abs_delta_sr_task_mean",
    "hfr",
    "hfr_task_mean",
    "sr_real_checker",
    "pearson",
    "pearson_reason",
    "spearman",
    "spearman_reason",
    "mmrv",
    "n_subtasks",
    "n_settings",
    "ci95",
    "ranking_ci95",
)
TASK_KEYS = ("sr_real", "sr_imag", "abs_delta_sr", "hfr", "sr_real_checker", "n_subtasks", "ci95")


def protocol(
    quick: bool, *, subtasks: int | None = None, seed: int | None = None, rounds: int = 5, judge: str = ""
) -> PairedProtocol:
    """The bench's pairs; ``judge``: a learned judge folder SR and HFR come from ("" = the hand-written reference)."""
    from pilworld.policies.registry import policy_names
    from simrig.tasks import TASK_NAMES

    base = PairedProtocol(
        tasks=tuple(TASK_NAMES),
        checkpoints=QUICK_CHECKPOINTS if quick else tuple(policy_names()),
        subtasks=subtasks or (QUICK_SUBTASKS if quick else FULL_SUBTASKS),
        rounds=rounds,
        judge=judge,
    )
    if seed is not None:
        base = replace(base, seed=seed)
    return base


def custom_variant(spec: str) -> ModelVariant:
    """``NAME=PATH``: a world model of the user's (any checkpoint folder) run as one more variant.

    The model runs as it is (no task adapter; its default sampling steps), so a folder from
    ``pilworld train composite`` or ``pilworld train`` compares with the table's rows on the same pairs.
    """
    name, sep, path = spec.partition("=")
    name, path = name.strip(), path.strip()
    if not sep or not name or not path:
        raise ValueError(f"--variants: expected a known name or NAME=PATH, got {spec!r}")
    if name in {v.name for v in standard_variants() + v2_variants()}:
        raise ValueError(f"--variants: {name!r} is a standard variant's name; give your model another name")
    v = ModelVariant(name, f"{name} ({path})", path, adapter="none", role="model", note=f"user model {path}")
    v.check()
    return v


def select_variants(quick: bool, names: Sequence[str] | None = None) -> list[ModelVariant]:
    """The variants to run: ``names`` (in that order) or, by mode, :data:`QUICK_VARIANTS` / :data:`FULL_VARIANTS`.

    A name of the form ``NAME=PATH`` adds the model folder at PATH as variant NAME (:func:`custom_variant`).
    """
    every = {v.name: v for v in standard_variants() + v2_variants()}  # the equal-budget rows: by name until trained
    if names:
        unknown = [n for n in names if n not in every and "=" not in n]
        if unknown:
            raise ValueError(
                f"--variants: unknown {unknown} (known: {', '.join(every)}; or NAME=PATH for a model folder)"
            )
        chosen = [every[n] if n in every else custom_variant(n) for n in names]
        if len({v.name for v in chosen}) != len(chosen):
            raise ValueError(f"--variants: a name appears twice in {list(names)}")
        if "pilworld" not in names:
            chosen.insert(0, every["pilworld"])  # the headline figures are the shipped model's
        return chosen
    if quick:
        return [every[n] for n in QUICK_VARIANTS]
    return [every[n] for n in FULL_VARIANTS]


def _pick(d: dict[str, Any], keys: Sequence[str]) -> dict[str, Any]:
    return {k: d[k] for k in keys if k in d}


def summarize_variant(result: dict[str, Any]) -> dict[str, Any]:
    """The table's row of one variant (overall, per task, single-step per view, speed)."""
    m = result["metrics"]
    single = m.get("single_step") or {}
    return {
        "label": result["variant"]["label"],
        "role": result["variant"]["role"],
        "world_model": result["variant"]["world_model"] or "packaged",
        "note": result["variant"].get("note", ""),
        "overall": _pick(m["overall"], OVERALL_KEYS),
        "tasks": {t: _pick(v, TASK_KEYS) for t, v in m["tasks"].items()},
        "settings": [
            {k: s[k] for k in ("task", "checkpoint", "sr_real", "sr_imag", "hfr", "n")} for s in m["settings"]
        ],
        "single_step": {
            "per_view": {
                v: {k: d.get(k) for k in ("psnr", "psnr_pooled", "ssim", "gain_over_frozen_pooled_db")}
                for v, d in (single.get("per_view") or {}).items()
            },
            "psnr_pooled": single.get("psnr_pooled"),
            "ssim": single.get("ssim"),
            "gain_over_frozen_pooled_db": single.get("gain_over_frozen_pooled_db"),
            "pairs_used": single.get("pairs_used"),
            "reason": single.get("reason"),
        },
        "failure_faithfulness": failure_faithfulness(result["out"]),
        "agreement": agreement(Verdicts.load(result["out"])),
        "imagined_seconds_per_subtask": result.get("imagined_seconds_per_subtask"),
        "stages_s": result["stages_s"],
        "out": result["out"],
    }


def _judges_row(metrics: dict[str, Any]) -> dict[str, Any]:
    """Which judges a variant's SR and HFR came from, and each judge's own rates on the same pairs."""
    j = metrics.get("judges") or {}
    per = {
        jid: {k: d.get(k) for k in ("sr_real", "sr_imag", "hfr", "pairs_both", "agreement_with_checker")}
        for jid, d in (j.get("per_judge") or {}).items()
        if d.get("kind") != "sim_state"
    }
    return {"selection": j.get("selection"), "per_judge": per, "learned": j.get("learned")}


def failure_faithfulness(run: str) -> dict[str, Any]:
    """On pairs whose real branch failed, the share whose imagined branch failed too (and the converse)."""
    from pilworld.data.judge_selection import read_selection
    from pilworld.data.pairs import load_pairs
    from pilworld.metrics.success import score_pairs

    scores = score_pairs(load_pairs(run), read_selection(run))
    both = [(s.real, s.imag) for s in scores if s.real is not None and s.imag is not None]
    fails = [i for r, i in both if r < 0.5]
    wins = [i for r, i in both if r >= 0.5]
    return {
        "real_failures": len(fails),
        "imagined_also_failed": (sum(1 for i in fails if i < 0.5) / len(fails)) if fails else None,
        "real_successes": len(wins),
        "imagined_also_succeeded": (sum(1 for i in wins if i >= 0.5) / len(wins)) if wins else None,
    }


def run_paired_bench(
    *,
    out: str | Path,
    rig: str | Path,
    quick: bool = False,
    variants: Sequence[str] | None = None,
    subtasks: int | None = None,
    seed: int | None = None,
    workers: int | None = None,
    progress: bool = True,
    real_from: str | Path | None = None,
    judge: str | Path | None = None,
) -> dict[str, Any]:
    """Every chosen variant on the protocol's pairs. ``judge``: the learned judge folder SR and HFR come from
    (default: the shipped one; "" = the hand-written reference alone)."""
    from pilworld.judges.learned.folder import load_judge
    from pilworld.judges.learned.shipped import SHIPPED_JUDGE

    t0 = time.monotonic()
    judge = str(SHIPPED_JUDGE if judge is None else judge)
    if judge:
        load_judge(judge)  # a missing or damaged folder: one line before hours of work
    proto = protocol(quick, subtasks=subtasks, seed=seed, judge=judge)
    chosen = select_variants(quick, variants)
    results = evaluate_variants(chosen, proto, out, rig=rig, workers=workers, progress=progress, real_from=real_from)
    rows = {name: summarize_variant(r) for name, r in results.items()}
    shipped = rows["pilworld"]
    out_json: dict[str, Any] = {
        "bench": "paired",
        "quick": quick,
        "protocol": {
            "tasks": list(proto.tasks),
            "checkpoints": list(proto.checkpoints),
            "subtasks": proto.subtasks,
            "rounds": proto.rounds,
            "seed0": proto.seed,
            "pairs_per_variant": proto.pairs,
            "judge": (
                f"learned success judge {judge} + the task-free hallucination detector (judge 'learned'); the "
                "hand-written reference (pilworld.judges.vision, judge 'vision') beside it on the same episodes"
                if judge
                else "the paper tasks' hand-written image judge + hallucination detector (pilworld.judges.vision)"
            ),
        },
        "judges": {name: _judges_row(r["metrics"]) for name, r in results.items()},
        "overall": shipped["overall"],
        "tasks": shipped["tasks"],
        "single_step": shipped["single_step"],
        "variants": rows,
        "targets": TARGETS,
        "paper": PAPER,
        "out": str(out),
        "machine": machine_info(),
        "wall_s": round(time.monotonic() - t0, 1),
    }
    baseline = next((name for name, r in rows.items() if r["role"] == "baseline"), None)
    out_json["baseline"] = rows[baseline] if baseline else None
    out_json["gamma_plus_rows"] = [n for n in GAMMA_PLUS_ROWS if n in rows]
    # The paper's directions, each a paired comparison on the same pairs (pilworld.bench.claims).
    verdicts = {name: Verdicts.load(r["out"]) for name, r in rows.items()}
    out_json["claims"] = paper_claims(verdicts)
    # What each step of the Γ⁺ ladder buys, paired against the step before it.
    out_json["gamma_plus_steps"] = steps(verdicts, GAMMA_PLUS_ROWS)
    return out_json


# The summary table, one row per variant (pilworld/bench/output.py aligns it).
PAIRED_COLUMNS = (
    Column("variant", 15, "variant", align="<"),
    Column("SR_real", 8, "sr_real", pct),
    Column("SR_imag", 8, "sr_imag", pct),
    Column("|ΔSR|", 7, "abs_delta_sr", pct),
    Column("HFR", 6, "hfr", num),
    Column("Pearson", 8, "pearson", num),
    Column("MMRV", 6, "mmrv", num),
    Column("head PSNR", 9, lambda row: row["head"].get("psnr_pooled"), num, align="<", sep="  "),
)


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        "--quick",
        action="store_true",
        help="3 tasks × 2 checkpoints × 3 subtasks, shipped v2, paper-faithful, Ctrl-World-style",
    )
    add_rig(parser)
    parser.add_argument(
        "--out", type=Path, default=None, help="run folders (default bench_runs/paired-quick|full); resumed"
    )
    parser.add_argument(
        "--variants",
        default="",
        help="comma-separated variants (default: by mode; see docs/RESULTS.md); NAME=PATH adds a model folder",
    )
    parser.add_argument(
        "--subtasks",
        type=int,
        default=None,
        help="subtasks per task × checkpoint (default 3 quick / 8: 120 pairs per variant)",
    )
    parser.add_argument("--seed", type=int, default=None, help="first layout seed (default 6000000)")
    parser.add_argument("--workers", type=int, default=None, help="judging processes (default: one per CPU)")
    parser.add_argument(
        "--real-from", type=Path, default=None, help="copy every variant's real branches from this run folder"
    )
    parser.add_argument(
        "--judge",
        default=None,
        help="learned judge folder SR and HFR come from (default: the shipped one; '' = the hand-written reference "
        "alone); the reference judges every run either way, beside it",
    )
    parser.add_argument("--chart", type=Path, default=None, help="PNG to draw (default OUT/paired.png)")
    add_json(parser)


def run(args: argparse.Namespace) -> int:
    """The table of every variant and its chart (``--chart``, default OUT/paired.png)."""
    # Imported here: the chart needs matplotlib, which the other users of this module do not.
    from pilworld.bench.charts import paired_table_chart

    at_least_one(args, "subtasks")
    out = run_folder(args, "paired")
    r = run_paired_bench(
        out=out,
        rig=args.rig,
        quick=args.quick,
        variants=parse_list(args.variants) or None,
        subtasks=args.subtasks,
        seed=args.seed,
        workers=args.workers,
        progress=not args.json,
        real_from=args.real_from,
        judge=args.judge,
    )
    r["chart"] = str(paired_table_chart(r["variants"], r["targets"], args.chart or out / "paired.png"))
    return emit(args, r, summary_lines(r))


def summary_lines(r: dict[str, Any]) -> list[str]:
    p = r["protocol"]
    rows = [
        {"variant": name, **row["overall"], "head": (row["single_step"]["per_view"] or {}).get("cam_high", {})}
        for name, row in r["variants"].items()
    ]
    return [
        f"paired ({'quick' if r['quick'] else 'full'}): {len(p['tasks'])} tasks × {len(p['checkpoints'])} checkpoints "
        f"× {p['subtasks']} subtasks, R={p['rounds']}, seeds from {p['seed0']}",
        *table(PAIRED_COLUMNS, rows),
        f"  targets: |ΔSR| ≤ 5 points, HFR ≥ 0.85, Pearson ≥ 0.95; chart {r['chart']}",
        f"  judge: {p['judge']}",
        *_judge_lines(r.get("judges") or {}),
    ]


def _judge_lines(judges: dict[str, Any]) -> list[str]:
    """Per variant, every judge's SR_real / SR_imag / HFR on the same pairs (the selected one counts)."""

    def fmt(x: Any, scale: float, digits: int) -> str:
        return "—" if x is None else f"{scale * float(x):.{digits}f}"

    lines = []
    for name, row in judges.items():
        chosen = (row.get("selection") or {}).get("judges")
        parts = [
            f"{jid}{'*' if chosen is None or jid in chosen else ''} {fmt(d.get('sr_real'), 100, 1)}/"
            f"{fmt(d.get('sr_imag'), 100, 1)} HFR {fmt(d.get('hfr'), 1, 2)}"
            for jid, d in row.get("per_judge", {}).items()
        ]
        lines.append(f"  {name:<15} by judge (SR_real/SR_imag %, * counts): {'; '.join(parts)}")
    return lines
