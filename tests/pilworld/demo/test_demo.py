"""``pilworld demo`` end to end at the smallest size: paired runs of every task, judged, metrics, report."""

from __future__ import annotations

import contextlib
import io
import json
from pathlib import Path

import pytest

from pilworld.cli.main import main
from pilworld.data.outcomes import read_outcomes
from pilworld.data.reader import EpisodeStore
from pilworld.demo import DEFAULT_CHECKPOINTS, demo_size, summary_table


@pytest.fixture(scope="module")
def demo_run(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, dict[str, object], str]:
    out = tmp_path_factory.mktemp("demo") / "run"
    buf = io.StringIO()
    with contextlib.redirect_stdout(buf):
        rc = main(["demo", "--out", str(out), "--subtasks", "1", "--rounds", "1", "--json"])
    assert rc == 0
    text = buf.getvalue()
    return out, json.loads(text.strip().splitlines()[-1]), text


def test_metrics_json_has_the_acceptance_keys(demo_run: tuple[Path, dict[str, object], str]) -> None:
    out, _, _ = demo_run
    metrics = json.loads((out / "metrics.json").read_text())
    assert set(metrics["tasks"]) == {"sort_cubes", "stack_bowls", "stack_blocks"}
    for m in metrics["tasks"].values():
        assert {"sr_real", "sr_imag", "abs_delta_sr", "hfr"} <= set(m)
    assert {"abs_delta_sr", "hfr", "pearson", "mmrv"} <= set(metrics["overall"])


def test_metric_values_follow_from_the_stored_verdicts(demo_run: tuple[Path, dict[str, object], str]) -> None:
    """The values, not only the keys: recomputed here from the outcomes table and the episodes."""
    out, _, _ = demo_run
    metrics = json.loads((out / "metrics.json").read_text())
    store = EpisodeStore(out)
    task_of = {i: json.loads(row["extra"])["sim_task"] for i, row in enumerate(store.episodes)}
    verdicts = read_outcomes(out)
    for task, m in metrics["tasks"].items():
        assert m["n_subtasks"] == len(DEFAULT_CHECKPOINTS)  # one subtask per checkpoint
        checker = [
            float(o.success) for o in verdicts if o.judge_id == "sim_checker" and task_of[o.episode_index] == task
        ]
        assert len(checker) == len(DEFAULT_CHECKPOINTS)
        assert m["sr_real_checker"] == pytest.approx(sum(checker) / len(checker))
        for key in ("sr_real", "sr_imag", "hfr"):
            assert m[key] is None or 0.0 <= m[key] <= 1.0, (task, key, m[key])
        if m["sr_real"] is not None and m["sr_imag"] is not None:
            assert m["abs_delta_sr"] == pytest.approx(abs(m["sr_imag"] - m["sr_real"]))
    overall = metrics["overall"]
    assert overall["abs_delta_sr"] is None or 0.0 <= overall["abs_delta_sr"] <= 1.0
    assert overall["pearson"] is None or -1.0 <= overall["pearson"] <= 1.0


def test_every_episode_is_judged_and_both_origins_are_stored(demo_run: tuple[Path, dict[str, object], str]) -> None:
    out, summary, _ = demo_run
    store = EpisodeStore(out)
    assert store.num_episodes == 2 * 3 * len(DEFAULT_CHECKPOINTS)
    assert {e["origin"] for e in store.episodes} == {"real", "imagined"}
    judged = {o.episode_index for o in read_outcomes(out) if o.judge_id == "vision"}
    assert judged == set(range(store.num_episodes))
    assert summary["pairs"] == 9


def test_sr_comes_from_the_shipped_learned_judge_with_the_reference_beside_it(
    demo_run: tuple[Path, dict[str, object], str],
) -> None:
    """Judge selection explicit in metrics.json: the learned judge counts; the hand-written one is shown beside."""
    from pilworld.judges.learned.shipped import SHIPPED_JUDGE

    out, summary, text = demo_run
    metrics = json.loads((out / "metrics.json").read_text())
    judges = metrics["judges"]
    assert judges["selection"]["judges"] == ["learned"] and judges["selection"]["set_by"] == "pilworld demo"
    assert judges["learned"]["folder"] == str(SHIPPED_JUDGE) and judges["learned"]["complete"]
    assert {"learned", "vision", "sim_checker"} <= set(judges["per_judge"])
    rows = {(o.episode_index, o.judge_id) for o in read_outcomes(out)}
    learned = {i for i, j in rows if j == "learned"}
    assert len(learned) + judges["learned"]["abstained"] == EpisodeStore(out).num_episodes
    if learned:
        assert judges["success"] in (["learned"], [])  # [] when it abstained on a branch of every pair
    assert summary["learned_judge"] == {
        "folder": str(SHIPPED_JUDGE),
        "judged": len(learned),
        "abstained": judges["learned"]["abstained"],
    }
    assert "SR and HFR from judge(s)" in text and "  vision " in text and "  learned " in text
    assert 'id="judges"' in (out / "report.html").read_text()


def test_a_bad_judge_folder_is_refused_before_any_run(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    bad = tmp_path / "judge"
    bad.mkdir()
    out = tmp_path / "run"
    assert main(["demo", "--out", str(out), "--subtasks", "1", "--rounds", "1", "--judge", str(bad)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "judge.json" in err[0] and not out.exists()


def test_report_and_summary_table(demo_run: tuple[Path, dict[str, object], str]) -> None:
    out, summary, text = demo_run
    html = (out / "report.html").read_text()
    assert html.count("<video") == 9
    assert "SR_real" in text and "Pearson" in text and "MMRV" in text
    assert summary["report_html"] == str(out / "report.html")


def test_rerun_resumes_without_redoing_work(demo_run: tuple[Path, dict[str, object], str]) -> None:
    out, _, _ = demo_run
    before = EpisodeStore(out).num_episodes
    with contextlib.redirect_stdout(io.StringIO()) as buf:
        assert main(["demo", "--out", str(out), "--subtasks", "1", "--rounds", "1", "--json"]) == 0
    again = json.loads(buf.getvalue().strip().splitlines()[-1])
    assert again["branches_run"] == 0 and EpisodeStore(out).num_episodes == before


def test_sizes_and_table() -> None:
    assert demo_size(False).checkpoints == DEFAULT_CHECKPOINTS and demo_size(False).subtasks == 6
    assert len(demo_size(True).checkpoints) == 5 and demo_size(True).subtasks == 20
    with pytest.raises(ValueError, match="subtasks"):
        demo_size(False, 0)
    table = summary_table({"tasks": {"t": {"sr_real": 0.5, "sr_imag": 0.25, "abs_delta_sr": 0.25, "hfr": 0.9}}})
    assert "50%" in table and "25%" in table and "0.90" in table
