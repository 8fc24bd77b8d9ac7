"""``pilworld bench judges`` and ``bench hallucination`` print one JSON object on their last line."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from pilworld.cli.main import main
from pilworld.paired import PairedConfig, paired_run
from pilworld.types import ChunkSpec


@pytest.fixture(scope="module")
def tiny_run(tmp_path_factory: pytest.TempPathFactory) -> Path:
    out = tmp_path_factory.mktemp("bench_judges") / "run"
    cfg = PairedConfig(
        rig="configs/rig/sim_dual_ur5e.yaml",
        task="sort_cubes",
        checkpoints=["scripted_step_30k"],
        subtasks=1,
        out=str(out),
        spec=ChunkSpec(rounds=2),
    )
    paired_run(cfg, progress=False)
    return out


def test_bench_judges_json(tiny_run: Path, capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["bench", "judges", str(tiny_run), "--json"]) == 0
    r = json.loads(capsys.readouterr().out.strip().splitlines()[-1])
    assert r["n"] == 1 and "sort_cubes" in r["per_task"]
    assert set(r["per_task"]["sort_cubes"]["confusion"]) == {"tp", "fp", "fn", "tn"}


def test_bench_hallucination_json(tiny_run: Path, capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["bench", "hallucination", str(tiny_run), "--per-fault", "1", "--json"]) == 0
    r = json.loads(capsys.readouterr().out.strip().splitlines()[-1])
    assert "clean" in r and "faults" in r and r["clean"]["n"] >= 1


def test_bench_hallucination_draws_each_fault_that_many_times(
    tiny_run: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    assert main(["bench", "hallucination", str(tiny_run), "--per-fault", "1", "--draws", "3", "--json"]) == 0
    r = json.loads(capsys.readouterr().out.strip().splitlines()[-1])
    assert r["draws"] == 3
    for fault, stats in r["faults"].items():
        assert stats["n"] + stats["skipped"] == 3 * r["episodes"], fault
        if stats["n"]:
            lo, hi = stats["detection_ci95"]
            assert lo <= stats["detection_rate"] <= hi, fault
    lo, hi = r["clean"]["false_positive_ci95"]
    assert lo <= r["clean"]["false_positive_rate"] <= hi


def test_wilson_interval() -> None:
    from pilworld.bench.hallucination import run_hallucination_bench, wilson

    assert wilson(90, 100) == pytest.approx([0.8256, 0.9448], abs=1e-4)
    assert wilson(0, 75)[0] == 0.0 and wilson(75, 75)[1] == 1.0  # type: ignore[index]
    assert wilson(0, 0) is None
    with pytest.raises(ValueError, match="draws"):
        run_hallucination_bench("unused", "unused", draws=0)
