"""A run's judge selection: only the selected judges' verdicts count in SR and HFR, recorded in the run folder
and stated in metrics.json; the other judges' rates stay beside them; bad files and ids are one line."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from pilworld.cli.main import main as cli
from pilworld.data.judge_selection import (
    SELECTION_FILE,
    JudgeSelectionError,
    parse_judge_ids,
    read_selection,
    write_selection,
)
from pilworld.data.outcomes import Outcome, record_outcomes
from pilworld.metrics import compute_run_metrics
from tests.pilworld.metrics.synthetic import ROUNDS, K, SynthPair, write_paired

T = 1 + ROUNDS * K
# (real, imagined, imagined t_h) by judge "learned" and by judge "vision" on four pairs of one task.
LEARNED = [(1, 1, None), (1, 0, 3), (0, 0, None), (0, 0, None)]
VISION = [(1, 1, None), (1, 1, None), (1, 0, 5), (0, 1, None)]


@pytest.fixture
def run(tmp_path: Path) -> Path:
    root = tmp_path / "run"
    write_paired(root, [SynthPair(task="a", checkpoint="c", subtask=i) for i in range(len(LEARNED))])
    rows = []
    for jid, plan in (("learned", LEARNED), ("vision", VISION)):
        for i, (real, imag, t_h) in enumerate(plan):
            rows.append(Outcome(2 * i, jid, "vision", bool(imag), T, t_h))
            rows.append(Outcome(2 * i + 1, jid, "vision", bool(real), T))
    rows += [Outcome(2 * i + 1, "sim_checker", "sim_state", True, T) for i in range(len(LEARNED))]
    record_outcomes(root, rows)
    return root


def _rates(plan: list[tuple[int, int, int | None]]) -> tuple[float, float, float]:
    real = sum(r for r, _, _ in plan) / len(plan)
    imag = sum(i for _, i, _ in plan) / len(plan)
    hfr = sum((T if t is None else t) / T for _, _, t in plan) / len(plan)
    return real, imag, hfr


def test_without_a_selection_every_both_branch_judge_counts(run: Path) -> None:
    m = compute_run_metrics(run, bootstrap=0, single_step=False)
    (lr, li, lh), (vr, vi, vh) = _rates(LEARNED), _rates(VISION)
    assert m["overall"]["sr_real"] == pytest.approx((lr + vr) / 2)
    assert m["overall"]["sr_imag"] == pytest.approx((li + vi) / 2)
    assert m["overall"]["hfr"] == pytest.approx((lh + vh) / 2)
    assert m["judges"]["selection"]["judges"] is None and m["judges"]["selection"]["set_by"] == "default"
    assert m["judges"]["success"] == ["learned", "vision"]


def test_a_selected_judge_alone_gives_sr_and_hfr_and_the_others_stay_beside_it(run: Path) -> None:
    write_selection(run, ["learned"], "a test")
    m = compute_run_metrics(run, bootstrap=0, single_step=False)
    real, imag, hfr = _rates(LEARNED)
    assert (m["overall"]["sr_real"], m["overall"]["sr_imag"]) == (pytest.approx(real), pytest.approx(imag))
    assert m["overall"]["hfr"] == pytest.approx(hfr)
    assert m["tasks"]["a"]["sr_real"] == pytest.approx(real)
    assert m["overall"]["sr_real_checker"] == 1.0  # the checker is reported apart either way
    assert m["judges"]["selection"] == {
        "judges": ["learned"],
        "rule": "only these judges' verdicts count in SR and HFR; every judge's own rates are in per_judge",
        "set_by": "a test",
    }
    assert m["judges"]["success"] == ["learned"] and m["judges"]["hallucination"] == ["learned"]
    vr, vi, _ = _rates(VISION)
    assert m["judges"]["per_judge"]["vision"]["sr_real"] == pytest.approx(vr)  # beside it, on the same pairs
    assert m["judges"]["per_judge"]["vision"]["sr_imag"] == pytest.approx(vi)


def test_a_selection_of_a_judge_without_verdicts_leaves_sr_undefined_with_the_reason(run: Path) -> None:
    write_selection(run, ["human_1"], "a test")
    m = compute_run_metrics(run, bootstrap=0, single_step=False)
    assert m["overall"]["sr_real"] is None and "none of the selected judges (human_1)" in m["overall"]["sr_real_reason"]
    assert m["judges"]["pairs_without_common_judge"] == len(LEARNED)


def test_judge_select_on_the_command_line(run: Path, capsys: pytest.CaptureFixture[str]) -> None:
    assert cli(["judge", "select", str(run), "vision", "--no-report", "--json"]) == 0
    out = json.loads(capsys.readouterr().out.strip().splitlines()[-1])
    assert out["selection"]["judges"] == ["vision"] and out["judges_with_verdicts"] == [
        "learned",
        "sim_checker",
        "vision",
    ]
    assert read_selection(run).judges == ("vision",)
    assert cli(["judge", "select", str(run)]) == 0  # without JUDGES: shows it, changes nothing
    assert "SR and HFR come from vision" in capsys.readouterr().out
    assert cli(["judge", "select", str(run), "all", "--no-report"]) == 0
    assert read_selection(run).judges is None and read_selection(run).set_by == "pilworld judge select"


def test_bad_input_is_one_line_and_changes_nothing(run: Path, capsys: pytest.CaptureFixture[str]) -> None:
    write_selection(run, ["learned"], "a test")
    before = (run / SELECTION_FILE).read_text()
    assert cli(["judge", "select", str(run), "nobody"]) != 0
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "nobody: no verdicts of that judge" in err[0] and "learned, sim_checker, vision" in err[0]
    assert cli(["judge", "select", str(run), "a b"]) != 0
    assert "comma-separated judge ids" in capsys.readouterr().err
    assert (run / SELECTION_FILE).read_text() == before
    assert cli(["judge", "select", str(run.parent), "learned"]) != 0
    assert "not a run folder" in capsys.readouterr().err


def test_a_damaged_selection_file_is_named(run: Path) -> None:
    (run / SELECTION_FILE).parent.mkdir(parents=True, exist_ok=True)
    for text in ("{not json", json.dumps({"format": "other"}), json.dumps({"format": "pilworld-judge-selection/1"})):
        (run / SELECTION_FILE).write_text(text)
        with pytest.raises(JudgeSelectionError, match=r"selection\.json: not a judge selection"):
            compute_run_metrics(run, bootstrap=0, single_step=False)


def test_parse_judge_ids(tmp_path: Path) -> None:
    assert parse_judge_ids("learned, human_1,learned") == ("learned", "human_1")
    assert parse_judge_ids(" all ") is None
    for bad in ("", ",", "a b", "x" * 65):
        with pytest.raises(JudgeSelectionError):
            parse_judge_ids(bad)
    with pytest.raises(JudgeSelectionError):  # the same rule for callers: "a,b" is not one id
        write_selection(tmp_path, ["a,b"], "a test")
    assert not (tmp_path / SELECTION_FILE).exists()
