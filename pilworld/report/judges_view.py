"""The report's "Judges" section: which judges' verdicts the results come from, each judge's own rates on the
same pairs, and the applied learned judge's validation figures (metrics.json ``judges``, docs/metrics.md).

Shown whenever metrics.json has a ``judges`` block; every missing value is "—". :func:`judges_text` gives the
same block as lines for the terminal (``pilworld demo``, ``judge apply``, ``judge select``).
"""

from __future__ import annotations

from collections.abc import Mapping
from html import escape
from typing import Any

from pilworld.report.metrics_view import DASH, fmt


def _e(value: object) -> str:
    return escape(str(value), quote=True)


def _num(value: Any, digits: int = 3) -> str:
    text = str(value) if isinstance(value, int) and not isinstance(value, bool) else fmt(value, digits)
    return f'<td class="num">{_e(text)}</td>'


def _selection_note(block: Mapping[str, Any]) -> str:
    selection = block.get("selection")
    if not isinstance(selection, Mapping) or selection.get("judges") is None:
        used = ", ".join(str(j) for j in block.get("success") or []) or DASH
        return f"SR and HFR average every judge with verdicts on both branches of a pair: {used}."
    chosen = ", ".join(str(j) for j in selection["judges"])
    return (
        f"SR and HFR come from the selected judge(s) {chosen} (set by {selection.get('set_by', DASH)}); "
        "the other judges' rates on the same pairs are shown for comparison."
    )


def _learned_note(learned: Mapping[str, Any]) -> str:
    v = learned.get("validation")
    v = v if isinstance(v, Mapping) else {}
    sha = str(learned.get("sha256") or "")[:12] or DASH
    abstained = learned.get("abstained")
    return (
        f"Learned judge {_e(learned.get('name', DASH))} (weights {_e(sha)}): out-of-fold agreement "
        f"{_e(fmt(v.get('accuracy_answered'), 3))} on the answered ones of {_e(v.get('episodes', DASH))} validation "
        "episodes, "
        f"abstaining on {_e(fmt(v.get('abstain_share'), 3))}; on this run it judged {_e(learned.get('judged', DASH))} "
        f"of {_e(learned.get('episodes', DASH))} episodes and left {_e(DASH if abstained is None else abstained)} to "
        f"people{'' if learned.get('complete', True) else ' (its pass did not finish)'}."
    )


def judges_section(metrics: Mapping[str, Any] | None) -> str:
    """HTML of the section, or "" when metrics.json has no judges block."""
    block = metrics.get("judges") if metrics is not None else None
    if not isinstance(block, Mapping):
        return ""
    per = block.get("per_judge")
    per = per if isinstance(per, Mapping) else {}
    selection = block.get("selection")
    chosen = selection.get("judges") if isinstance(selection, Mapping) else None
    out = [
        '<section id="judges"><h2>Judges</h2>',
        f'<p class="note" id="judges-selection">{_e(_selection_note(block))}</p>',
    ]
    learned = block.get("learned")
    if isinstance(learned, Mapping):
        out.append(f'<p class="note" id="judges-learned">{_learned_note(learned)}</p>')
    rows = []
    for jid, d in per.items():
        if not isinstance(d, Mapping):
            continue
        counts = "—" if d.get("kind") == "sim_state" else ("yes" if chosen is None or jid in chosen else "no")
        rows.append(
            f'<tr data-judge="{_e(jid)}"><td>{_e(jid)}</td><td>{_e(d.get("kind", DASH))}</td><td>{counts}</td>'
            + _num(d.get("pairs_both"))
            + _num(d.get("sr_real"), 2)
            + _num(d.get("sr_imag"), 2)
            + _num(d.get("hfr"), 2)
            + _num(d.get("agreement_with_checker"), 3)
            + "</tr>"
        )
    head = ["judge", "kind", "counts", "pairs (both branches)", "SR real", "SR imagined", "HFR", "agrees with checker"]
    th = "".join(f"<th>{_e(h)}</th>" for h in head)
    out.append(f'<table id="judges-table"><thead><tr>{th}</tr></thead><tbody>{"".join(rows)}</tbody></table>')
    out.append("</section>")
    return "".join(out)


def _pct(x: Any) -> str:
    return DASH if x is None else f"{100 * float(x):.0f}%"


def judges_text(judges: Mapping[str, Any], sr_real_checker: float | None) -> list[str]:
    """Which judges SR and HFR came from, and every judge's own rates on the same pairs, as terminal lines."""
    selection = judges.get("selection")
    chosen = selection.get("judges") if isinstance(selection, Mapping) else None
    used = "every judge with verdicts on both branches" if chosen is None else ", ".join(chosen)
    lines = [f"SR and HFR from judge(s) {used}; each judge on its own:"]
    per = judges.get("per_judge")
    for jid, d in (per if isinstance(per, Mapping) else {}).items():
        if d.get("kind") == "sim_state":
            lines.append(f"  {jid:<12} SR_real {_pct(sr_real_checker)} (the simulator's privileged checker)")
            continue
        lines.append(
            f"  {jid:<12} SR_real {_pct(d.get('sr_real'))}, SR_imag {_pct(d.get('sr_imag'))} over "
            f"{d.get('pairs_both', 0)} pairs; agrees with the checker on {_pct(d.get('agreement_with_checker'))} "
            "of real episodes"
        )
    return lines
