"""Paired runs of a task given as a file: episodes record the task's name and file hash; a bad file, or one the
rig cannot build, is refused in one line before the run folder exists; a hardware rig needs no objects."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from pilworld.cli.main import main
from pilworld.data.reader import EpisodeStore
from pilworld.paired.operator import ConsoleOperator
from pilworld.paired.runner import CONFIG_FILE
from pilworld.types import Subtask
from simrig.tasks import load_task

ROOT = Path(__file__).resolve().parents[3]
SIM = str(ROOT / "configs" / "rig" / "sim_dual_ur5e.yaml")
FAKE = str(ROOT / "configs" / "rig" / "fake_dual_ur5e.yaml")
PACKAGED = ROOT / "configs" / "tasks" / "sort_cubes.yaml"
INSTRUCTION = "put the three cubes into the slots, smallest first."

HARDWARE_ONLY = """\
name: pour_water
instruction: "pour the water into the bowl."
subtasks:
  - operator_setup: "a full cup on the left, the bowl in the middle"
    operator_success: "the water is in the bowl and none on the table"
"""


def _copy(tmp_path: Path, name: str) -> Path:
    """The packaged sort_cubes task saved elsewhere under another name (a user's task file)."""
    text = PACKAGED.read_text(encoding="utf-8").replace("name: sort_cubes", f"name: {name}")
    path = tmp_path / "tasks" / f"{name}.yaml"
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(text, encoding="utf-8")
    return path


def _paired(out: Path, task: Path | str, *extra: str, rig: str = SIM) -> list[str]:
    return ["paired", "run", "--rig", rig, "--task", str(task), "--subtasks", "1", "--rounds", "1",
            "--out", str(out), *extra]  # fmt: skip


def _episodes(root: Path) -> list[dict[str, object]]:
    store = EpisodeStore(root)
    eps = [store.load(i) for i in range(store.num_episodes)]
    return [{**e.extra, "instruction": e.task} for e in eps]


@pytest.fixture(scope="module")
def file_run(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, Path]:
    tmp = tmp_path_factory.mktemp("task_file_run")
    task = _copy(tmp, "my_sort")
    out = tmp / "run"
    assert main([*_paired(out, task, "--instruction", INSTRUCTION, "--json")]) == 0
    return task, out


def test_a_task_file_runs_and_its_episodes_carry_name_and_hash(file_run: tuple[Path, Path]) -> None:
    task, out = file_run
    digest = load_task(task).digest
    eps = _episodes(out)
    assert len(eps) == 2  # the imagined and the real branch of one pair
    for e in eps:
        assert e["instruction"] == INSTRUCTION  # the instruction given with --instruction is the one recorded
        assert e["task"] == "my_sort"
        assert str(e["pair"]).startswith("my_sort/")
        assert e["sim_task"] == "my_sort" and e["task_sha256"] == digest
    config = json.loads((out / CONFIG_FILE).read_text())
    assert config["task_sha256"] == {"my_sort": digest} and config["instruction"] == INSTRUCTION
    starts = EpisodeStore(out / "starts")
    start = starts.load(0)
    assert start.extra["task"] == "my_sort" and start.extra["task_sha256"] == digest
    assert start.extra["start"]["instruction"] == INSTRUCTION


def test_an_edited_task_file_does_not_resume_the_run(
    file_run: tuple[Path, Path], tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    task, out = file_run
    edited = tmp_path / "my_sort.yaml"
    edited.write_text(task.read_text(encoding="utf-8").replace("mass: 0.05", "mass: 0.06"), encoding="utf-8")
    before = (out / CONFIG_FILE).read_text()
    assert main(_paired(out, edited, "--instruction", INSTRUCTION)) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "different settings" in err[0] and "task_sha256" in err[0], err
    assert (out / CONFIG_FILE).read_text() == before


@pytest.mark.parametrize("problem", ["broken", "missing", "hardware_only", "twice", "blank_instruction"])
def test_a_refused_run_leaves_no_folder(tmp_path: Path, capsys: pytest.CaptureFixture[str], problem: str) -> None:
    out = tmp_path / "run"
    task: Path | str
    extra: list[str] = []
    if problem == "broken":
        task = tmp_path / "broken.yaml"
        task.write_text("name: broken\ninstruction: x\nsubtasks: []\n", encoding="utf-8")
    elif problem == "missing":
        task = tmp_path / "nowhere.yaml"
    elif problem == "hardware_only":
        task = tmp_path / "pour.yaml"
        task.write_text(HARDWARE_ONLY, encoding="utf-8")
    elif problem == "twice":
        task = f"{_copy(tmp_path, 'sort_cubes')},sort_cubes"  # two different files named sort_cubes
    else:
        task, extra = "sort_cubes", ["--instruction", "   "]
    assert main(_paired(out, task, *extra)) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("pilworld: error: --"), err
    assert not out.exists()


def test_record_starts_refuses_a_hardware_only_task_on_the_simulated_rig(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    task = tmp_path / "pour.yaml"
    task.write_text(HARDWARE_ONLY, encoding="utf-8")
    out = tmp_path / "starts"
    assert main(["paired", "record-starts", "--task", str(task), "--count", "1", "--out", str(out)]) == 2
    assert "has no objects" in capsys.readouterr().err
    assert not out.exists()


def test_a_hardware_rig_takes_a_task_without_objects_and_asks_for_an_operator(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """Without a terminal the error is the operator one, not a refusal of the task; --unattended cannot run
    a task the fake rig's simulator cannot lay out."""
    task = tmp_path / "pour.yaml"
    task.write_text(HARDWARE_ONLY, encoding="utf-8")
    out = tmp_path / "run"
    assert main(_paired(out, task, rig=FAKE)) == 1
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "operator" in err[0] and "terminal" in err[0] and "no objects" not in err[0], err
    assert not out.exists()
    assert main(_paired(out, task, "--unattended", rig=FAKE)) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("pilworld: error: --unattended:") and "no objects" in err[0], err
    assert not out.exists()


def test_the_operator_sees_the_task_files_notes() -> None:
    told: list[str] = []
    answers = iter(["", "y"])
    operator = ConsoleOperator(ask=lambda _: next(answers), tell=told.append)
    sub = Subtask("pour_water", 0, "pour the water into the bowl.", 0)
    operator.set_up(sub, "ckpt", setup="a full cup on the left")
    assert operator.judge(sub, "ckpt", success="the water is in the bowl") is True
    assert "Set-up: a full cup on the left" in told and "Success means: the water is in the bowl" in told


def test_the_fake_rig_runs_a_new_task_file_unattended(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    task = _copy(tmp_path, "fake_sort")
    out = tmp_path / "run"
    assert main([*_paired(out, task, "--unattended", "--json", rig=FAKE)]) == 0
    summary = json.loads(capsys.readouterr().out.strip().splitlines()[-1])
    assert summary["branches_run"] == 2
    eps = _episodes(out)
    assert {str(e["task_sha256"]) for e in eps} == {load_task(task).digest}
    assert all(str(e["pair"]).startswith("fake_sort/") for e in eps)


def test_imagine_reruns_a_task_files_starts_given_the_file(
    file_run: tuple[Path, Path], tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    task, run = file_run
    base = ["imagine", "--starts", str(run), "--checkpoints", "scripted_step_10k", "--no-judge"]
    out = tmp_path / "imagined"
    # Without the file, a scripted checkpoint has nothing to act on: my_sort is no packaged task.
    assert main([*base, "--out", str(out)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "my_sort" in err[0] and "--task" in err[0], err
    assert not out.exists()
    # Another file of that name is not the task the starts were laid out from.
    edited = tmp_path / "edited.yaml"
    edited.write_text(task.read_text(encoding="utf-8").replace("mass: 0.05", "mass: 0.06"), encoding="utf-8")
    assert main([*base, "--out", str(out), "--task", str(edited)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "sha256" in err[0], err
    assert not out.exists()
    assert main([*base, "--out", str(out), "--task", str(task), "--json"]) == 0
    (ep,) = _episodes(out)
    assert ep["task"] == ep["sim_task"] == "my_sort" and ep["task_sha256"] == load_task(task).digest
    assert ep["instruction"] == INSTRUCTION  # the starts' own (recorded with --instruction)
