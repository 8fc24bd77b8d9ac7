"""The report's "Human judges" section: metrics.json ``human_agreement`` (pilworld.metrics.agreement) as tables.

Shown only when the run has human verdicts; every missing or undefined value is "—" with the reason
from metrics.json as a tooltip, as in the metrics table.
"""

from __future__ import annotations

from collections.abc import Mapping
from html import escape
from typing import Any

from pilworld.report.metrics_view import DASH, fmt


def _e(value: object) -> str:
    return escape(str(value), quote=True)


def _cell(entry: Mapping[str, Any], key: str, digits: int = 3) -> str:
    reason = entry.get(f"{key}_reason")
    title = f' title="{_e(reason)}"' if isinstance(reason, str) and reason else ""
    value = entry.get(key)
    text = str(value) if isinstance(value, int) and not isinstance(value, bool) else fmt(value, digits)
    return f'<td class="num"{title}>{_e(text)}</td>'


def _map(value: Any) -> Mapping[str, Any]:
    return value if isinstance(value, Mapping) else {}


def _table(table_id: str, head: list[str], rows: list[str]) -> str:
    th = "".join(f"<th>{_e(h)}</th>" for h in head)
    return f'<table id="{table_id}"><thead><tr>{th}</tr></thead><tbody>{"".join(rows)}</tbody></table>'


def agreement_section(metrics: Mapping[str, Any] | None) -> str:
    """HTML of the section, or "" when metrics.json has no human verdicts."""
    block = metrics.get("human_agreement") if metrics is not None else None
    if not isinstance(block, Mapping) or not block.get("judges"):
        return ""
    out = ['<section id="human"><h2>Human judges</h2>']
    judges = ", ".join(str(j) for j in block["judges"])
    out.append(f'<p class="note">Judges {_e(judges)}; episodes labelled by two or more: '
               f"{_e(block.get('episodes_shared', DASH))}.</p>")  # fmt: skip
    human = block.get("human_only")
    overall = human.get("overall") if isinstance(human, Mapping) else None
    if isinstance(overall, Mapping):
        keys = ("sr_real", "sr_imag", "abs_delta_sr", "hfr", "n_judged")
        row = "<tr><td>human judges only</td>" + "".join(_cell(overall, k, 2) for k in keys) + "</tr>"
        out.append(_table("human-metrics", ["", "SR real", "SR imagined", "|ΔSR|", "HFR", "pairs"], [row]))
    success, hall = _map(block.get("success")), _map(block.get("hallucination"))
    rows = [
        "<tr><td>success</td>" + _cell(success, "episodes") + _cell(success, "fleiss_kappa")
        + _cell(success, "unanimous_share") + f'<td class="num">{DASH}</td>' * 3 + "</tr>"
    ]  # fmt: skip
    for origin, h in hall.items():
        if not isinstance(h, Mapping):
            continue
        spread = _map(h.get("frame_spread"))
        rows.append(
            f"<tr><td>hallucination ({_e(origin)} episodes)</td>" + _cell(h, "episodes")
            + _cell(h, "presence_fleiss_kappa") + _cell(h, "agree_none_share") + _cell(h, "agree_some_share")
            + _cell(spread, "mad_median", 1) + _cell(spread, "range_median", 1) + "</tr>"
        )  # fmt: skip
    out.append(
        _table(
            "human-agreement",
            ["between humans", "episodes", "Fleiss κ", "all agree / none", "all marked", "frame MAD", "frame range"],
            rows,
        )
    )
    rows = []
    for human_id, refs in _map(block.get("vs_other_judges")).items():
        for ref, v in _map(refs).items():
            if isinstance(v, Mapping):
                rows.append(
                    f"<tr><td>{_e(human_id)}</td><td>{_e(ref)}</td>" + _cell(v, "episodes")
                    + _cell(v, "success_agreement") + _cell(v, "success_cohen_kappa")
                    + _cell(v, "hallucination_presence_agreement") + _cell(v, "frame_abs_diff_median", 1) + "</tr>"
                )  # fmt: skip
    if rows:
        head = ["human", "other judge", "episodes", "success agreement", "Cohen κ", "hallucination yes/no agreement",
                "median |Δ frame|"]  # fmt: skip
        out.append(_table("human-vs-judges", head, rows))
    out.append(
        '<p class="note">Fleiss κ over episodes labelled by two or more human judges (1 = perfect, 0 = chance). '
        "First unanimous column: success rows, share of episodes where all agree; hallucination rows, share where "
        "all saw none. Frame MAD / range: median over episodes of the median absolute deviation / range of the "
        "marked first hallucination frames. Human-only SR and HFR use the human verdicts alone (the paper's "
        "judges); the metrics table above averages them with the automatic judges.</p></section>"
    )
    return "".join(out)
