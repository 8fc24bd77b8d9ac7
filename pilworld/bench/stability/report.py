"""The human summary ``pilworld bench stability`` prints above the JSON: per model, every probe in a line or two."""

from __future__ import annotations

from typing import Any

from pilworld.bench.output import num, pct


def summary_lines(r: dict[str, Any]) -> list[str]:
    p = r["probe_protocol"]
    lines = [
        f"stability ({'quick' if r['quick'] else 'full'}): {len(r['models'])} model(s), {p['starts']} probe starts, "
        f"{len(r['refused'])} probe chunk(s) refused, {r['wall_s']} s; chart {r['chart']}"
    ]
    for name, m in r["models"].items():
        lines.append(f"[{name}] {m['label']}")
        lines += _model_lines(m)
    return lines


def _model_lines(m: dict[str, Any]) -> list[str]:
    rows = m["horizon"]["rows"]
    f = m["failure_faithfulness"]
    lines = [
        "  horizon R " + "".join(f"{row['rounds']:>7}" for row in rows),
        "  HFR       " + "".join(f"{num(row['hfr'], 3):>7}" for row in rows),
        f"  failure faithfulness: {pct(f['imagined_also_failed'])} % of {f['real_failures']} real failures also "
        f"failed imagined; {pct(f['imagined_also_succeeded'])} % of {f['real_successes']} successes succeeded",
        "  counterfactual, head MSE ratio model/sim: "
        + ", ".join(
            f"vs {row['alternative']} {num(row['cam_high']['ratio_median'])}" for row in m["counterfactual"]["rows"]
        ),
    ]
    errors = m["calibration"]["rows"] + m["robot_mismatch"]["rows"]
    lines.append(f"  head PSNR {num(errors[0]['psnr_head'])} dB on the right rig; change with a wrong one, dB:")
    for row in errors[1:]:
        if row["applies"]:
            lines.append(
                f"    {row['label']}: {num(row['delta_db'])} ("
                + ", ".join(f"{v} {num(d)}" for v, d in row["delta_per_view"].items())
                + ")"
            )
        else:
            lines.append(f"    {row['label']}: does not reach this model")
    lines.append(
        "  OOD actions → head PSNR: "
        + ", ".join(f"{row['kind']} {num(row['psnr_head'])}" for row in m["ood_actions"]["rows"])
    )
    sh = m["action_shuffle"]
    head = sh["per_view"].get("cam_high") or {}
    lines.append(
        f"  action shuffle ({sh['rounds']} rounds, {sh['n']} starts), head view: MSE ratio model/sim "
        f"{num(head.get('ratio_median'))}, futures differ in {pct(head.get('distinct_share'))} %; PSNR shuffled "
        f"{num(head.get('psnr_shuffled'))} vs own {num(head.get('psnr_own'))} dB; deterministic "
        f"{pct(sh['deterministic_share'])} %"
    )
    return lines
