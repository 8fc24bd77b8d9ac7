"""``pilworld bench world-model`` on a tiny held-out set (one run each of two checkpoints on stack_blocks),
with the frozen baseline standing in for a trained model."""

from __future__ import annotations

import dataclasses
import json
import sys
import types
from pathlib import Path
from typing import Any

import pytest
import torch

import pilworld.collection.collect as collect_mod
from pilworld.bench.world_model import (
    HELDOUT_SEED0,
    heldout_checkpoints,
    heldout_dataset,
    run_world_model_bench,
)
from pilworld.cli.main import main
from pilworld.config.rig import RigConfig
from pilworld.world_model.base import FrozenWorldModel, WorldModelInfo

ROOT = Path(__file__).resolve().parents[3]
SIM = ROOT / "configs" / "rig" / "sim_dual_ur5e.yaml"
TASK = "stack_blocks"  # 2 subtasks: the cheapest task to run whole


def _info(size: int = 128, history: int = 5) -> WorldModelInfo:
    views = RigConfig.load(SIM).cameras
    return WorldModelInfo(views=tuple(views), height=size, width=size, future=15, history=history)


@pytest.fixture(scope="module")
def cache(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return tmp_path_factory.mktemp("wm_bench_cache")


@pytest.fixture(scope="module")
def heldout(cache: Path) -> Path:
    return heldout_dataset(SIM, tasks=[TASK], episodes=1, cache_dir=cache, workers=1, progress=False)


@pytest.fixture(scope="module")
def result(heldout: Path, cache: Path) -> dict[str, Any]:
    info = _info()
    return run_world_model_bench(
        FrozenWorldModel(info),
        heldout=heldout,
        no_history=FrozenWorldModel(dataclasses.replace(info, history=0)),
        clips=3,
        batch=2,
        repeats=3,
        rig=SIM,
        progress=False,
        cache_dir=cache,
    )


def test_heldout_set_uses_unseen_seeds_and_is_reused(
    heldout: Path, cache: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    marker = json.loads((heldout.parent / "heldout.json").read_text())
    assert marker["seeds"] == [HELDOUT_SEED0] and marker["checkpoints"] == list(heldout_checkpoints())
    assert marker["collect"]["episodes"] == 4  # 2 checkpoints × 1 run × 2 subtasks
    again = lambda *a, **k: pytest.fail("a complete held-out set was collected again")  # noqa: E731
    monkeypatch.setattr(collect_mod, "collect", again)
    assert heldout_dataset(SIM, tasks=[TASK], episodes=1, cache_dir=cache, progress=False) == heldout
    with pytest.raises(ValueError, match=r"seed0: seeds \[19\] were used for the training set"):
        heldout_dataset(SIM, tasks=[TASK], episodes=2, seed0=19, cache_dir=cache, progress=False)


def test_frozen_model_scores_and_json_keys(result: dict[str, Any]) -> None:
    views = list(_info().views)
    for key in (
        "psnr", "ssim", "per_view", "per_frame", "psnr_frozen", "ssim_frozen", "per_view_frozen",
        "per_frame_frozen", "gain_over_frozen_db", "gain_over_frozen_db_overall", "lpips_absent_reason", "psnr_pooled",
        "psnr_pooled_frozen", "exact", "exact_frozen", "gain_over_frozen_pooled_db",
        "chunk_latency_ms", "chunk_latency_ms_p90", "realtime_factor", "steps", "image_size", "K", "views",
        "torch_threads", "machine", "heldout", "no_history", "clips",
    ):  # fmt: skip
        assert key in result, key
    assert result["clips"] == 3 and result["K"] == 15 and result["views"] == views
    assert result["image_size"] == [128, 128] and not result["resized"]
    assert result["psnr"] == result["psnr_frozen"] and result["ssim"] == result["ssim_frozen"]
    assert result["gain_over_frozen_db"] == dict.fromkeys(views, 0.0)
    assert result["gain_over_frozen_pooled_db"] == dict.fromkeys(views, 0.0)
    assert set(result["per_view"]) == set(views)
    assert len(result["per_frame"]["psnr"]) == 15 and len(result["per_frame"]["ssim"]) == 15
    # Copying the current frame gets worse the further into the future: frame 15 is below frame 1.
    assert result["per_frame"]["psnr"][-1] < result["per_frame"]["psnr"][0]
    assert 10 < result["psnr"] < 100 and 0 < result["ssim"] < 1
    nh = result["no_history"]
    assert nh["history_frames_given"] == 0 and nh["psnr"] == result["psnr"]
    assert nh["history_gain_db"] == dict.fromkeys(views, 0.0) and nh["gain_over_frozen_db_overall"] == 0.0
    assert 0 <= result["exact_frozen"] <= 1 and set(result["per_view"]["cam_high"]) == {
        "psnr",
        "ssim",
        "psnr_pooled",
        "exact",
    }
    assert result["chunk_latency_ms"] > 0 and result["chunk_latency_ms_p90"] >= result["chunk_latency_ms"]
    assert result["realtime_factor"] > 0 and result["torch_threads"] >= 1
    held = result["heldout"]
    assert held["seeds"] == [HELDOUT_SEED0] and held["seeds_used_in_training"] is False
    assert held["video_mode"] == "lossless" and held["tasks"] == [TASK]
    json.dumps(result)  # serialisable as is


def test_a_smaller_model_is_scored_at_its_own_size(heldout: Path, cache: Path) -> None:
    out = run_world_model_bench(
        FrozenWorldModel(_info(size=64)), heldout=heldout, clips=1, repeats=1, rig=SIM, progress=False, cache_dir=cache
    )
    assert out["image_size"] == [64, 64] and out["resized"] and out["no_history"] is None
    assert out["dataset_image_size"] == [[128, 128]] * 3


def test_a_model_wanting_more_history_than_the_clips_gets_invalid_padding(heldout: Path, cache: Path) -> None:
    """As in the imagined branch's memory at a rollout's start: the missing front frames are flagged invalid."""
    seen: list[torch.Tensor] = []

    class Spy(FrozenWorldModel):
        def predict_batch(self, batch, *, steps=None, seed=0):  # type: ignore[no-untyped-def]
            seen.append(batch.history_valid.clone())
            assert batch.history.shape[2] == 9 and batch.state is not None
            return super().predict_batch(batch, steps=steps, seed=seed)

    run_world_model_bench(
        FrozenWorldModel(_info()),
        heldout=heldout,
        no_history=Spy(_info(history=9)),
        clips=1,
        repeats=1,
        rig=SIM,
        progress=False,
        cache_dir=cache,
    )
    assert seen and not seen[0][:, :4].any()
    swapped = dataclasses.replace(_info(), views=tuple(reversed(_info().views)))
    with pytest.raises(ValueError, match="no_history: views"):
        run_world_model_bench(
            FrozenWorldModel(_info()), heldout=heldout, no_history=FrozenWorldModel(swapped), rig=SIM, progress=False
        )


def test_cli_prints_a_table_then_the_json(
    heldout: Path, cache: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str], tmp_path: Path
) -> None:
    class Loaded(FrozenWorldModel):
        def without_history(self) -> FrozenWorldModel:
            return FrozenWorldModel(dataclasses.replace(self.info, history=0))

    loaded: list[Path] = []

    def load_world_model(path: Path, adapter: str | None = None) -> Loaded:
        loaded.append(path)
        return Loaded(_info())

    fake = types.ModuleType("pilworld.world_model.loader")
    fake.load_world_model = load_world_model  # type: ignore[attr-defined]
    monkeypatch.setitem(sys.modules, "pilworld.world_model.loader", fake)
    monkeypatch.setenv("PILWORLD_CACHE", str(cache))  # the held-out set of the fixture is reused
    ckpt = tmp_path / "model"
    ckpt.mkdir()
    args = ["bench", "world-model", "--checkpoint", str(ckpt), "--tasks", TASK, "--episodes", "1"]
    assert main([*args, "--clips", "1", "--repeats", "1", "--json"]) == 0
    lines = capsys.readouterr().out.strip().splitlines()
    out = json.loads(lines[-1])
    assert loaded == [ckpt] and out["checkpoint"] == str(ckpt) and out["no_history"]["history_frames_given"] == 0
    assert lines[0].startswith("world-model (Loaded, 128x128, K=15): 1 held-out clips")
    assert any(line.split()[0] == "cam_high" for line in lines[1:-1])
    assert main([*args, "--no-ablation", "--clips", "1", "--repeats", "1", "--json"]) == 0
    assert json.loads(capsys.readouterr().out.strip().splitlines()[-1])["no_history"] is None
    assert main(["bench", "world-model", "--checkpoint", str(tmp_path / "missing")]) == 2
    assert "--checkpoint:" in capsys.readouterr().err
