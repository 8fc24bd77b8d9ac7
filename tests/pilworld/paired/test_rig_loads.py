"""A paired run and the demo read the rig file once and pass the loaded rig down (stations, Γ, the episode
store's spec, the judges, the report)."""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path

import pytest

from pilworld.config.rig import RigConfig
from pilworld.types import ChunkSpec
from simrig.files import SIM_RIG


@pytest.fixture
def loads(monkeypatch: pytest.MonkeyPatch) -> Iterator[list[str]]:
    """Every rig file loaded while the test runs."""
    seen: list[str] = []
    load = RigConfig.load.__func__  # type: ignore[attr-defined]

    def counting(cls: type[RigConfig], path: str | Path) -> RigConfig:
        seen.append(str(path))
        return load(cls, path)  # type: ignore[no-any-return]

    monkeypatch.setattr(RigConfig, "load", classmethod(counting))
    yield seen


def test_a_paired_run_loads_its_rig_once(tmp_path: Path, loads: list[str]) -> None:
    from pilworld.paired.runner import PairedConfig, paired_run

    cfg = PairedConfig(
        rig=str(SIM_RIG),
        task="sort_cubes",
        checkpoints=["scripted_step_30k"],
        subtasks=1,
        out=str(tmp_path / "run"),
        spec=ChunkSpec(rounds=1),
    )
    summary = paired_run(cfg, progress=False)
    assert summary["branches_run"] == 2
    assert loads == [str(SIM_RIG)]


@pytest.mark.slow
def test_the_demo_loads_its_rig_once(tmp_path: Path, loads: list[str]) -> None:
    from pilworld.demo import run_demo

    result = run_demo(tmp_path / "demo", rig=SIM_RIG, subtasks=1, rounds=1, progress=False, workers=1)
    assert result["branches_run"] > 0 and Path(result["report_html"]).is_file()
    assert loads == [str(SIM_RIG)]
