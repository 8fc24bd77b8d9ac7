"""``pilworld bench paired-timing --json``: per-branch wall times as one JSON object on the last line."""

from __future__ import annotations

import json

import pytest

from pilworld.cli.main import main


def test_bench_paired_timing_json(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["bench", "paired-timing", "--subtasks", "1", "--rounds", "1", "--json"]) == 0
    out = json.loads(capsys.readouterr().out.strip().splitlines()[-1])
    assert out["subtasks"] == 1 and out["rounds"] == 1
    assert out["robot_seconds_per_subtask"] == pytest.approx(1.5)
    for origin in ("real", "imagined"):
        b = out[origin]
        assert b["seconds_per_subtask"]["median"] > 0
        assert b["env_ms_per_round"]["median"] > 0 and b["policy_ms_per_round"]["median"] > 0
        assert b["realtime_factor"] > 0


def test_bench_paired_timing_rejects_zero_rounds(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["bench", "paired-timing", "--rounds", "0"]) == 2
    assert "--rounds" in capsys.readouterr().err
