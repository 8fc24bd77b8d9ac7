"""The learned judge's workflow on a rig, no code (docs/judges.md, "On a real rig"), end to end on the fake rig.

A pilot of paired subtasks of a task file no code knows, with an operator's verdicts at the terminal →
``pilworld judge train --labels operator`` → ``pilworld judge apply`` gives every episode of the run a verdict
or leaves it to people → ``pilworld annotate serve --abstained`` queues exactly those → their labels join
the learned verdicts in metrics.json, which names the judge that gave them.
"""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from pilworld.annotate.server import AnnotationServer
from pilworld.annotate.store import Label
from pilworld.cli.annotate import abstained_episodes
from pilworld.cli.main import main
from pilworld.data.outcomes import read_outcomes
from pilworld.judges.learned.apply import LEARNED_ID, RECORD
from pilworld.paired.config import PairedConfig
from pilworld.paired.operator import OPERATOR_JUDGE, ConsoleOperator
from pilworld.paired.runner import paired_run
from pilworld.types import ChunkSpec

# ~2 min on 2 cores (a 6-subtask pilot through the fake rig's drivers, four small trainings, an imagined run):
# in the slow set with the other end-to-end acceptance checks, to keep the default suite near its 15 minutes.
pytestmark = pytest.mark.slow

ROOT = Path(__file__).resolve().parents[4]
FAKE = str(ROOT / "configs" / "rig" / "fake_dual_ur5e.yaml")
TASK = Path(__file__).parent / "data" / "puck_on_coaster.yaml"  # in no package, read by no judge
SUBTASKS = 6
VERDICTS = ["y", "n", "n", "y", "y", "n"]  # the operator's, one per subtask


# A deliberately unsure judge: 8 steps on 6 labels, abstaining on up to half (both paths get exercised).
UNSURE = ("--steps", "8", "--abstain-budget", "0.5")


def _train(pilot: Path, out: Path, *settings: str) -> int:
    """``pilworld judge train`` on the pilot's operator verdicts, two folds, with ``settings``."""
    return main(["judge", "train", "--data", str(pilot), "--labels", "operator", "--out", str(out), "--rig", FAKE,
                 "--folds", "2", *settings])  # fmt: skip


@pytest.fixture(scope="module")
def pilot(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """Six paired subtasks on the fake rig; the operator sets up each scene (Enter) and says yes or no."""
    answers = iter(a for v in VERDICTS for a in ("", v))
    operator = ConsoleOperator(ask=lambda _: next(answers), tell=lambda _: None)
    out = tmp_path_factory.mktemp("workflow") / "pilot"
    cfg = PairedConfig(
        rig=FAKE,
        task=str(TASK),
        checkpoints=["scripted_step_05k"],
        subtasks=SUBTASKS,
        out=str(out),
        spec=ChunkSpec(rounds=1),
    )
    paired_run(cfg, progress=False, operator=operator)
    return out


def test_operator_verdicts_train_a_judge_that_judges_the_run_and_queues_the_rest(
    pilot: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    said = [o for o in read_outcomes(pilot) if o.judge_id == OPERATOR_JUDGE]
    assert len(said) == SUBTASKS and sorted(o.success for o in said) == sorted(v == "y" for v in VERDICTS)

    judge = tmp_path / "judge"
    assert _train(pilot, judge, *UNSURE, "--json") == 0
    trained = json.loads(capsys.readouterr().out.strip().splitlines()[-1])
    assert trained["validation"]["episodes"] == SUBTASKS  # the operator's verdicts, real branch only

    assert main(["judge", "apply", str(judge), str(pilot), "--rig", FAKE, "--json"]) == 0
    applied = json.loads(capsys.readouterr().out.strip().splitlines()[-1])
    episodes = 2 * SUBTASKS  # both branches of every pair
    rows = {o.episode_index for o in read_outcomes(pilot) if o.judge_id == LEARNED_ID}
    abstained = applied["abstained"]
    assert applied["episodes"] == episodes and applied["judged"] == len(rows)
    assert sorted(rows | set(abstained)) == list(range(episodes)) and not rows & set(abstained)
    assert rows and abstained  # a judge this unsure (8 steps on 6 labels) answers some and abstains on others

    metrics = json.loads((pilot / "metrics.json").read_text())
    learned = metrics["judges"]["learned"]
    assert learned["folder"] == str(judge.resolve()) and learned["abstained"] == len(abstained)
    assert learned["trained_on"]["labels"] == "operator"
    assert LEARNED_ID in metrics["judges"]["per_judge"]
    assert metrics["judges"]["selection"]["judges"] == [LEARNED_ID]  # SR and HFR come from it now

    # The people's queue is exactly what the judge left to them; their labels join the outcomes.
    assert abstained_episodes(pilot) == abstained
    server = AnnotationServer(pilot, judges=1, episodes=abstained)
    assert sorted(server.app.catalog.queue(1)) == abstained
    server.httpd.server_close()
    server.store.put_label(1, abstained[0], Label(success=True, first_hallucination_frame=None, category=None))
    assert main(["annotate", "export", str(pilot), "--no-report"]) == 0
    humans = [o for o in read_outcomes(pilot) if o.judge_id == "human_1"]
    assert [o.episode_index for o in humans] == [abstained[0]]


def test_imagined_rollouts_thereafter_are_judged_by_the_learned_judge(
    pilot: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """``imagine --judge``: success by the learned judge (abstentions listed), hallucinations by the task-free
    detector in the same rows; the paper tasks' hand-written judge, which refuses this task, is not asked."""
    judge = tmp_path / "judge"
    assert _train(pilot, judge, *UNSURE) == 0
    out = tmp_path / "imagined"
    argv = ["imagine", "--starts", str(pilot), "--task", str(TASK), "--checkpoints", "scripted_step_10k",
            "--out", str(out), "--judge", str(judge), "--judge-workers", "1", "--json"]  # fmt: skip
    assert main(argv) == 0
    summary = json.loads(capsys.readouterr().out.strip().splitlines()[-1])
    rows = read_outcomes(out)
    episodes = summary["branches_planned"]
    assert episodes == SUBTASKS
    learned = {o.episode_index for o in rows if o.judge_id == LEARNED_ID}
    assert sorted(learned | set(summary["judged"]["abstained"])) == list(range(episodes))
    assert learned and {o.judge_id for o in rows} == {LEARNED_ID}  # not the hand-written "vision"
    record = json.loads((out / RECORD).read_text())
    assert record["complete"] and record["abstained"] == summary["judged"]["abstained"]
    bad = tmp_path / "not_a_judge"
    bad.mkdir()
    assert main([*argv[:-5], "--out", str(tmp_path / "x"), "--judge", str(bad)]) == 2
    assert "judge.json" in capsys.readouterr().err and not (tmp_path / "x").exists()


def test_apply_resumes_and_another_judge_replaces_the_verdicts(
    pilot: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """A second apply of the same judge changes nothing; another judge's verdicts replace the first's."""
    a, b = tmp_path / "a", tmp_path / "b"
    assert _train(pilot, a, "--steps", "4") == 0
    assert _train(pilot, b, "--steps", "4", "--seed", "1") == 0
    assert main(["judge", "apply", str(a), str(pilot), "--rig", FAKE, "--no-report"]) == 0
    first = {o.episode_index: o.success for o in read_outcomes(pilot) if o.judge_id == LEARNED_ID}
    assert main(["judge", "apply", str(a), str(pilot), "--rig", FAKE, "--no-report"]) == 0
    assert {o.episode_index: o.success for o in read_outcomes(pilot) if o.judge_id == LEARNED_ID} == first
    capsys.readouterr()
    assert main(["judge", "apply", str(b), str(pilot), "--rig", FAKE, "--no-report"]) == 0
    record = json.loads((pilot / RECORD).read_text())
    assert record["folder"] == str(b.resolve()) and record["complete"]
    out = capsys.readouterr().out
    assert ("withdrew" in out) == bool(first)  # the first judge's verdicts went, if it gave any


def test_a_release_crop_judge_is_evaluated_with_the_rig(
    pilot: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """``judge evaluate --rig`` hands the rig to a judge that reads where a gripper let go (kinematics, head camera)."""
    judge = tmp_path / "crop"
    assert _train(pilot, judge, "--steps", "4", "--release-crop", "16") == 0
    capsys.readouterr()
    argv = ["judge", "evaluate", str(judge), "--data", str(pilot), "--labels", "operator", "--rig", FAKE, "--json"]
    assert main(argv) == 0
    assert json.loads(capsys.readouterr().out.strip().splitlines()[-1])["episodes"] == SUBTASKS


def test_abstained_needs_an_applied_judge(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    run = tmp_path / "run"
    run.mkdir()
    assert main(["annotate", "serve", str(run), "--judges", "1", "--abstained"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "judge apply" in err[0], err


def test_paired_run_with_a_judge_is_judged_selected_and_reported(
    pilot: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """``paired run --judge JUDGE``: the run judged by it when it ends (as ``judge apply``), SR and HFR from it."""
    judge = tmp_path / "judge"
    assert _train(pilot, judge, *UNSURE) == 0
    out = tmp_path / "run"
    argv = ["paired", "run", "--rig", FAKE, "--unattended", "--task", str(TASK), "--checkpoints",
            "scripted_step_05k", "--subtasks", "1", "--rounds", "1", "--seed", "77", "--out", str(out),
            "--judge", str(judge), "--json"]  # fmt: skip
    capsys.readouterr()
    assert main(argv) == 0
    summary = json.loads(capsys.readouterr().out.strip().splitlines()[-1])
    rows = {o.episode_index for o in read_outcomes(out) if o.judge_id == LEARNED_ID}
    assert summary["judge"]["judged"] == len(rows) and sorted(rows | set(summary["judge"]["abstained"])) == [0, 1]
    metrics = json.loads((out / "metrics.json").read_text())
    assert metrics["judges"]["selection"] == {
        "judges": [LEARNED_ID],
        "rule": "only these judges' verdicts count in SR and HFR; every judge's own rates are in per_judge",
        "set_by": "pilworld paired run --judge",
    }
    assert (out / "report.html").is_file() and 'id="judges"' in (out / "report.html").read_text()
    bad = tmp_path / "not_a_judge"
    bad.mkdir()
    assert main([*argv[:-3], "--out", str(tmp_path / "x"), "--judge", str(bad)]) == 2
    assert "judge.json" in capsys.readouterr().err and not (tmp_path / "x").exists()
