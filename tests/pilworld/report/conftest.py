"""One tiny paired run (2 pairs, R = 1) with fake judge verdicts and metrics.json, and its report, per session."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import pytest

from pilworld.paired import PairedConfig, paired_run
from pilworld.report import build_report
from pilworld.types import ChunkSpec
from tests.pilworld.report.fakes import judge_run, write_fake_metrics

SIM = "configs/rig/sim_dual_ur5e.yaml"
CHECKPOINTS = ["scripted_step_30k"]
SPEC = ChunkSpec(rounds=1)


@dataclass(frozen=True)
class Built:
    run: Path
    report: Path
    hallucinations: dict[str, int | None]  # pair id → the fake judge's first hallucination frame (imagined)


@pytest.fixture(scope="session")
def paired_dir(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, dict[str, int | None]]:
    out = tmp_path_factory.mktemp("report") / "run"
    cfg = PairedConfig(rig=SIM, task="sort_cubes", checkpoints=CHECKPOINTS, subtasks=2, out=str(out), spec=SPEC)
    paired_run(cfg, progress=False)
    marks = judge_run(out)
    write_fake_metrics(out, CHECKPOINTS)
    return out, marks


@pytest.fixture(scope="session")
def built(paired_dir: tuple[Path, dict[str, int | None]]) -> Built:
    run, marks = paired_dir
    return Built(run, build_report(run), marks)
