"""The report's "Judges" section: the selection, every judge's rates on the same pairs, the learned judge's figures."""

from __future__ import annotations

from pilworld.report.judges_view import judges_section

PER = {
    "learned": {"kind": "vision", "pairs_both": 9, "sr_real": 0.5, "sr_imag": 0.25, "hfr": 0.9},
    "vision": {"kind": "vision", "pairs_both": 9, "sr_real": 0.6, "sr_imag": 0.3, "hfr": 0.8},
    "sim_checker": {"kind": "sim_state", "pairs_both": 0, "sr_real": None, "sr_imag": None, "hfr": None},
}
PER["learned"]["agreement_with_checker"] = 0.8
PER["vision"]["agreement_with_checker"] = 0.95


def test_selected_judge_and_the_reference_beside_it() -> None:
    learned = {
        "name": "sim_paper_flat",
        "sha256": "ab" * 32,
        "validation": {"episodes": 600, "accuracy_answered": 0.93, "abstain_share": 0.04},
        "episodes": 18,
        "judged": 17,
        "abstained": 1,
        "complete": True,
    }
    html = judges_section(
        {
            "judges": {
                "selection": {"judges": ["learned"], "set_by": "pilworld demo"},
                "success": ["learned"],
                "per_judge": PER,
                "learned": learned,
            }
        }
    )
    assert 'id="judges"' in html and "selected judge(s) learned (set by pilworld demo)" in html
    assert "out-of-fold agreement 0.930 on the answered ones of 600 validation episodes" in html
    assert "judged 17 of 18 episodes and left 1 to people" in html and "abababababab" in html
    row = html.split('data-judge="vision"')[1].split("</tr>")[0]
    assert "<td>no</td>" in row and "0.60" in row and "0.950" in row
    assert "<td>yes</td>" in html.split('data-judge="learned"')[1].split("</tr>")[0]


def test_default_selection_and_no_judges_block() -> None:
    html = judges_section({"judges": {"selection": {"judges": None}, "success": ["vision"], "per_judge": PER}})
    assert "average every judge with verdicts on both branches of a pair: vision" in html
    assert 'id="judges-learned"' not in html
    assert judges_section({}) == "" and judges_section(None) == ""
