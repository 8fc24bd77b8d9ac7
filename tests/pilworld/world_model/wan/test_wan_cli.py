"""The Wan2.1 backend from the command line: ``paired run --world-model DIR`` with a Wan2.1 folder
(tiny random weights at the simulated rig's views and size; diffusers' own test sizes)."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from pilworld.cli.main import main
from pilworld.config.rig import RigConfig
from pilworld.types import ChunkSpec
from pilworld.world_model.base import WorldModelInfo
from simrig.files import SIM_RIG

pytest.importorskip("diffusers")


@pytest.mark.slow
def test_a_paired_run_runs_the_wan_backend_from_its_folder(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    from pilworld.world_model.wan.backend import WanWorldModel

    rig, spec = RigConfig.load(SIM_RIG), ChunkSpec()
    info = WorldModelInfo(
        views=rig.cameras,
        height=rig.image_size.height,
        width=rig.image_size.width,
        future=spec.frames,
        history=spec.history,
    )
    folder = tmp_path / "wan"
    WanWorldModel.tiny_random(info).save_pretrained(folder)
    out = tmp_path / "run"
    args = ["paired", "run", "--task", "sort_cubes", "--checkpoints", "scripted_step_30k", "--subtasks", "1"]
    assert main([*args, "--rounds", "1", "--world-model", str(folder), "--out", str(out), "--json"]) == 0
    summary = json.loads(capsys.readouterr().out.strip().splitlines()[-1])
    assert summary["branches_run"] == 2
    stored = json.loads((out / "paired_config.json").read_text())
    assert stored["world_model"] == str(folder)
