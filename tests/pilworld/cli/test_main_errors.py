"""The CLI's error contract: a run failure (policy, operator, rig) is one line and exit 1; bad input exit 2."""

from __future__ import annotations

import argparse

import pytest

import pilworld.cli.main as cli
from hw_drivers.errors import ProtectiveStopError, StaleObservationError
from pilworld.paired.operator import OperatorUnavailableError
from pilworld.policies.base import PolicyError


def _parser_raising(err: BaseException) -> argparse.ArgumentParser:
    def handler(args: argparse.Namespace) -> int:
        raise err

    parser = argparse.ArgumentParser(prog="pilworld")
    parser.add_argument("--debug", action="store_true")
    parser.set_defaults(handler=handler)
    return parser


@pytest.mark.parametrize(
    ("err", "status"),
    [
        (PolicyError("ws://127.0.0.1:1", "no reply", kind="timeout"), 1),
        (OperatorUnavailableError("an operator is needed: stdin is not a terminal"), 1),
        (StaleObservationError("safety filter", "the observation is 1.4 s old\n(limit 1.0 s)"), 1),
        (ProtectiveStopError("left arm", "protective stop"), 1),
        (ValueError("--subtasks: expected at least 1"), 2),
        (FileNotFoundError("rig.yaml not found"), 2),
    ],
)
def test_one_line_and_exit_status(
    monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str], err: BaseException, status: int
) -> None:
    monkeypatch.delenv("PILWORLD_DEBUG", raising=False)
    monkeypatch.setattr(cli, "build_parser", lambda: _parser_raising(err))
    assert cli.main([]) == status
    lines = capsys.readouterr().err.splitlines()
    assert len(lines) == 1 and lines[0].startswith("pilworld: error: "), lines


@pytest.mark.parametrize(
    ("err", "status"), [(ProtectiveStopError("left arm", "stop"), 1), (ValueError("--subtasks: expected 1..9"), 2)]
)
def test_debug_shows_the_traceback(
    monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str], err: BaseException, status: int
) -> None:
    """``--debug`` adds the traceback; the exit status is the documented one still (not Python's 1)."""
    monkeypatch.setattr(cli, "build_parser", lambda: _parser_raising(err))
    assert cli.main(["--debug"]) == status
    stderr = capsys.readouterr().err
    assert "Traceback (most recent call last)" in stderr and type(err).__name__ in stderr
    assert stderr.splitlines()[-1].startswith("pilworld: error: ")


def test_os_errors_name_the_file_first(monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]) -> None:
    monkeypatch.delenv("PILWORLD_DEBUG", raising=False)
    monkeypatch.setattr(cli, "build_parser", lambda: _parser_raising(FileExistsError(17, "File exists", "/x/out")))
    assert cli.main([]) == 2
    assert capsys.readouterr().err == "pilworld: error: /x/out: File exists\n"
