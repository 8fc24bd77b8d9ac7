"""``pilworld bench world-model-presets``: parameter counts and latency per preset."""

from __future__ import annotations

import json

import pytest

from pilworld.bench.world_model_presets import run_presets_bench
from pilworld.cli.main import main
from pilworld.world_model.latent.config import preset
from pilworld.world_model.latent.model import PilWorldModel


def test_presets_bench_counts_parameters_and_times_a_chunk() -> None:
    result = run_presets_bench(["tiny"], repeats=1, progress=False)
    tiny = result["presets"]["tiny"]
    model = PilWorldModel(preset("tiny"))
    assert tiny["params"] == sum(p.numel() for p in model.parameters())
    assert tiny["params"] == tiny["params_vae"] + tiny["params_denoiser"]
    assert tiny["image_size"] == [32, 32] and tiny["K"] == 15 and tiny["views"] == 3
    assert tiny["steps"] == preset("tiny").steps
    assert tiny["chunk_latency_ms"] > 0 and tiny["realtime_factor"] > 0


def test_presets_bench_cli_json_and_unknown_preset(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["bench", "world-model-presets", "--presets", "tiny", "--repeats", "1", "--steps", "1", "--json"]) == 0
    out = capsys.readouterr().out.strip().splitlines()
    data = json.loads(out[-1])
    assert data["bench"] == "world-model-presets" and data["presets"]["tiny"]["steps"] == 1
    assert main(["bench", "world-model-presets", "--presets", "huge", "--json"]) == 2
    assert "unknown 'huge'" in capsys.readouterr().err
