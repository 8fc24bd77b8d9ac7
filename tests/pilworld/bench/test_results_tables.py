"""``python -m pilworld.bench.results_tables``: RESULTS.md's tables from the benches' JSON files."""

from __future__ import annotations

from pathlib import Path

import pytest

from pilworld.bench.results_tables import main


def test_missing_empty_and_broken_results_are_named_not_raised(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """A bench still running leaves its JSON empty, a failed one a log line: each is reported and skipped."""
    (tmp_path / "paired-full.json").write_text("")
    (tmp_path / "speed-accuracy-full.json").write_text("Traceback (most recent call last):\n")
    assert main([str(tmp_path)]) == 0
    out = capsys.readouterr().out
    assert f"({tmp_path / 'paired-full.json'} is not a bench result" in out
    assert f"({tmp_path / 'speed-accuracy-full.json'} is not a bench result" in out
    assert f"({tmp_path / 'stability-full.json'} missing)" in out
