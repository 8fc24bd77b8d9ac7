"""A tiny paired run (2 checkpoints × 1 subtask, R = 1: 4 episodes of 16 frames) built once per session.

Tests that write into a run (labels, outcomes, metrics) get their own copy (``run`` fixture).
"""

from __future__ import annotations

import shutil
from collections.abc import Iterator
from pathlib import Path

import pytest

from pilworld.annotate.server import AnnotationServer
from pilworld.paired import PairedConfig, paired_run
from pilworld.types import ChunkSpec
from tests.pilworld.annotate.client import Client

CHECKPOINTS = ["scripted_step_30k", "scripted_step_01k"]


@pytest.fixture(scope="session")
def pristine_run(tmp_path_factory: pytest.TempPathFactory) -> Path:
    out = tmp_path_factory.mktemp("annotate") / "run"
    cfg = PairedConfig(
        rig="configs/rig/sim_dual_ur5e.yaml",
        task="sort_cubes",
        checkpoints=CHECKPOINTS,
        subtasks=1,
        out=str(out),
        spec=ChunkSpec(rounds=1),
    )
    paired_run(cfg, progress=False)
    return out


@pytest.fixture
def run(pristine_run: Path, tmp_path: Path) -> Path:
    """A private copy of the run (the run's own folder name, so its path is unlike the pristine one)."""
    return Path(shutil.copytree(pristine_run, tmp_path / "run_copy"))


@pytest.fixture
def server(run: Path) -> Iterator[AnnotationServer]:
    srv = AnnotationServer(run, judges=2).start()
    try:
        yield srv
    finally:
        srv.stop()


@pytest.fixture
def judge1(server: AnnotationServer) -> Client:
    return Client(server.url, server.tokens[1])


@pytest.fixture
def judge2(server: AnnotationServer) -> Client:
    return Client(server.url, server.tokens[2])
