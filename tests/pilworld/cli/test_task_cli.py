"""``pilworld task check|show|try``: a task file checked, its subtask starts drawn, its checkpoints tried."""

from __future__ import annotations

import json
from pathlib import Path

import cv2
import pytest

from pilworld.cli.main import main
from pilworld.config.rig import RigConfig
from simrig.tasks import check_task_file, load_task

ROOT = Path(__file__).resolve().parents[3]
SIM = ROOT / "configs" / "rig" / "sim_dual_ur5e.yaml"
SORT = ROOT / "configs" / "tasks" / "sort_cubes.yaml"

BROKEN = """\
name: Broken Task
instruction: ""
objects:
  - {name: cube, shape: box, size: [0.04, 0.04, 0.04]}
subtasks: []
"""

HARDWARE_ONLY = """\
name: pour_water
instruction: "pour the water into the bowl."
subtasks:
  - operator_setup: "a full cup on the left, the bowl in the middle"
    operator_success: "the water is in the bowl and none on the table"
"""


def _lines(text: str) -> list[str]:
    return [line for line in text.splitlines() if line.strip()]


def test_check_a_valid_file(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["task", "check", str(SORT)]) == 0
    (line,) = _lines(capsys.readouterr().out)
    digest = load_task(SORT).digest
    assert "OK" in line and "'sort_cubes'" in line and "3 objects" in line and "3 subtasks" in line
    assert digest[:12] in line


def test_check_a_broken_file_lists_every_problem(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    path = tmp_path / "broken.yaml"
    path.write_text(BROKEN, encoding="utf-8")
    assert main(["task", "check", str(path), "--json"]) == 1
    out = _lines(capsys.readouterr().out)
    problems = check_task_file(path)
    assert len(problems) >= 3  # the name, the instruction, the cube's mass, the subtasks
    assert out[:-1] == problems  # one line per problem, then the JSON
    assert all(line.startswith(f"{path}: ") and "field '" in line for line in out[:-1])
    summary = json.loads(out[-1])
    assert summary["ok"] is False and summary["files"][0]["problems"] == problems


def test_check_a_hardware_only_file(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    path = tmp_path / "pour.yaml"
    path.write_text(HARDWARE_ONLY, encoding="utf-8")
    assert main(["task", "check", str(path)]) == 0
    (line,) = _lines(capsys.readouterr().out)
    assert "no objects" in line and "1 subtask," in line


def test_show_draws_every_view_of_every_subtask_start(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    out = tmp_path / "pictures" / "sort.png"  # a folder that does not exist yet is made
    assert main(["task", "show", str(SORT), "--seed", "3", "--out", str(out), "--json"]) == 0
    summary = json.loads(_lines(capsys.readouterr().out)[-1])
    rig = RigConfig.load(SIM)
    image = cv2.imread(str(out))
    assert image is not None
    rows, views = load_task(SORT).num_subtasks, len(rig.cameras)
    assert image.shape == (rows * rig.image_size.height, views * rig.image_size.width, 3)
    assert summary["views"] == list(rig.cameras) and summary["subtasks"] == rows


@pytest.mark.parametrize(
    "out, expected", [("folder", "is a folder"), ("picture.jpg", "expected a .png"), ("ok.png", "has no objects")]
)
def test_show_refuses_in_one_line_before_simulating(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], out: str, expected: str
) -> None:
    (tmp_path / "folder.png").mkdir()
    task = tmp_path / "pour.yaml"
    task.write_text(HARDWARE_ONLY, encoding="utf-8")
    target = tmp_path / ("folder.png" if out == "folder" else out)
    assert main(["task", "show", str(task), "--out", str(target)]) == 2
    err = _lines(capsys.readouterr().err)
    assert len(err) == 1 and err[0].startswith("pilworld: error:") and expected in err[0], err
    assert out == "folder" or not target.exists()


def test_try_reports_rates_and_spread_as_json(capsys: pytest.CaptureFixture[str]) -> None:
    argv = ["task", "try", "sort_cubes", "--subtasks", "1", "--checkpoints", "scripted_step_30k", "--workers", "1"]
    assert main([*argv, "--json"]) == 0
    out = _lines(capsys.readouterr().out)
    summary = json.loads(out[-1])
    assert summary["task"] == "sort_cubes" and summary["subtasks"] == 1
    assert set(summary["rates"]) == {"scripted_step_30k"} and 0.0 <= summary["rates"]["scripted_step_30k"] <= 1.0
    assert summary["spread"]["holds"] is False  # one checkpoint cannot spread
    assert summary["task_sha256"] == load_task("sort_cubes").digest and summary["wall_s"] >= 0
    assert any("scripted_step_30k" in line for line in out[:-1])


def test_try_refuses_unknown_checkpoints_and_hardware_only_tasks(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    assert main(["task", "try", "sort_cubes", "--checkpoints", "nope"]) == 2
    assert "--checkpoints" in capsys.readouterr().err
    task = tmp_path / "pour.yaml"
    task.write_text(HARDWARE_ONLY, encoding="utf-8")
    assert main(["task", "try", str(task)]) == 2
    err = _lines(capsys.readouterr().err)
    assert err == [f"pilworld: error: {task}: task 'pour_water' has no objects: the simulated rig cannot build it"]
