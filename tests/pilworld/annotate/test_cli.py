"""``pilworld annotate status|export|serve``: output and one-line errors (serve itself: test_kill.py)."""

from __future__ import annotations

from pathlib import Path

import pytest

from pilworld.annotate.store import AnnotationStore, Label
from pilworld.cli.main import main


def test_status_and_export(run: Path, capsys: pytest.CaptureFixture[str]) -> None:
    store = AnnotationStore(run)
    store.ensure_judges(3)
    store.put_label(2, 1, Label(True, None, None))
    assert main(["annotate", "status", str(run)]) == 0
    assert capsys.readouterr().out.splitlines() == [
        "Judge 1: labelled 0 of 4",
        "Judge 2: labelled 1 of 4",
        "Judge 3: labelled 0 of 4",
    ]
    assert main(["annotate", "export", str(run), "--no-report"]) == 0
    out = capsys.readouterr().out
    assert "human_1 0, human_2 1, human_3 0" in out and "metrics: " in out and "report: " not in out


@pytest.mark.parametrize(
    ("argv", "message"),
    [
        (["serve", "{run}", "--judges", "0"], "--judges: expected an integer in 1..100"),
        (["serve", "{run}", "--judges", "2", "--host", "0.0.0.0"], "--allow-remote"),
        (["serve", "{run}"], "--judges: "),
        (["serve", "{empty}", "--judges", "1"], "not a LeRobot dataset"),
        (["serve", "{missing}", "--judges", "1"], "is not a folder"),
        (["status", "{run}"], "pilworld annotate serve"),
        (["export", "{empty}"], "not a LeRobot dataset"),
    ],
)
def test_clear_errors(
    run: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str], argv: list[str], message: str
) -> None:
    (tmp_path / "empty").mkdir()
    paths = {"run": str(run), "empty": str(tmp_path / "empty"), "missing": str(tmp_path / "missing")}
    assert main(["annotate", *(a.format(**paths) for a in argv)]) == 2
    err = capsys.readouterr().err
    assert err.startswith("pilworld: error: ") and message in err and err.count("\n") == 1
    assert not (tmp_path / "empty" / "annotations.sqlite").exists()
    if argv[0] == "serve":
        assert not (run / "annotations.sqlite").exists()  # nothing created by a refused start
