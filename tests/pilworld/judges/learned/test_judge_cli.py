"""``pilworld judge train|evaluate|show`` on a tiny dataset: what they print, write and refuse."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from pilworld.cli.main import main

from .synthetic import write_labelled


@pytest.fixture(scope="module")
def data(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, Path]:
    base = tmp_path_factory.mktemp("cli")
    return write_labelled(base / "train", episodes=40), write_labelled(base / "held", episodes=16, first=500)


def _last_json(out: str) -> dict[str, object]:
    return json.loads(out.strip().splitlines()[-1])


def test_train_show_evaluate(data: tuple[Path, Path], tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    train, held = data
    judge = tmp_path / "J"
    assert (
        main(["judge", "train", "--data", str(train), "--out", str(judge), "--folds", "2", "--steps", "60", "--json"])
        == 0
    )
    out = _last_json(capsys.readouterr().out)
    assert out["validation"]["episodes"] == 40  # type: ignore[index]
    assert main(["judge", "show", str(judge), "--json"]) == 0
    shown = _last_json(capsys.readouterr().out)
    assert shown["format"] == "pilworld-judge/1" and shown["data"]["labels"] == "sim_checker"  # type: ignore[index]
    assert main(["judge", "evaluate", str(judge), "--data", str(held), "--degrade", "coarse", "--json"]) == 0
    result = _last_json(capsys.readouterr().out)
    assert result["episodes"] == 16 and result["degrade"] == "coarse"
    # a second train into the same folder is refused and leaves the judge as it was
    before = (judge / "judge.json").read_bytes()
    assert main(["judge", "train", "--data", str(train), "--out", str(judge)]) == 2
    assert "already holds a judge" in capsys.readouterr().err
    assert (judge / "judge.json").read_bytes() == before


@pytest.mark.parametrize(
    ("argv", "said"),
    [
        (["--labels", "operator"], "no 'operator' labels"),
        (["--folds", "1"], "--folds: expected an integer in 2..20"),
        (["--steps", "0"], "--steps: expected an integer in 1..100,000"),
        (["--seed", "-1"], "--seed: expected an integer in 0..4,294,967,295"),
    ],
)
def test_bad_input_is_one_line_and_writes_nothing(
    data: tuple[Path, Path], tmp_path: Path, capsys: pytest.CaptureFixture[str], argv: list[str], said: str
) -> None:
    out = tmp_path / "J"
    assert main(["judge", "train", "--data", str(data[0]), "--out", str(out), *argv]) == 2
    err = capsys.readouterr().err.strip()
    assert said in err and len(err.splitlines()) == 1
    assert not out.exists()


def test_a_missing_dataset_or_judge_is_named(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["judge", "train", "--data", str(tmp_path / "nope"), "--out", str(tmp_path / "J")]) == 2
    assert "nope: not a folder" in capsys.readouterr().err
    assert main(["judge", "show", str(tmp_path / "J")]) == 2
    assert "no such judge folder" in capsys.readouterr().err
