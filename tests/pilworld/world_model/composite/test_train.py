"""Training world model v2 on the tiny synthetic dataset: the cache, the loss going down, exact resume."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from safetensors.numpy import load_file

from pilworld.config.rig import RigConfig
from pilworld.world_model.composite.cache import CacheSpec, build_cache
from pilworld.world_model.composite.model import CompositeWorldModel
from pilworld.world_model.composite.train import TrainSettings, train_composite
from pilworld.world_model.loader import load_world_model

from ..training.synthetic_data import write_dataset


@pytest.fixture(scope="module")
def dataset(tmp_path_factory: pytest.TempPathFactory) -> Path:
    with pytest.MonkeyPatch.context() as mp:
        mp.setenv("PILWORLD_CACHE", str(tmp_path_factory.mktemp("clip_cache")))
        return write_dataset(tmp_path_factory.mktemp("v2") / "ds")


def _settings(dataset: Path, steps: int) -> TrainSettings:
    return TrainSettings(
        data=str(dataset), steps=steps, batch=6, width=8, work_size=8, cache_size=32, max_clips=12, frames_per_clip=2
    )


def test_cache_is_deterministic_and_refuses_other_settings(dataset: Path, tmp_path: Path, rig32: RigConfig) -> None:
    spec = CacheSpec(str(dataset), "unused", size=32, frames_per_clip=2, max_clips=6)
    a = build_cache(spec, tmp_path / "a", rig=rig32, workers=1, progress=False)
    b = build_cache(spec, tmp_path / "b", rig=rig32, workers=2, progress=False)
    for name in ("inputs", "targets", "scalars", "grips"):
        np.testing.assert_array_equal(np.load(a / f"{name}.npy"), np.load(b / f"{name}.npy"))
    meta = json.loads((a / "cache.json").read_text())
    assert meta["complete"] and meta["samples"] == 6 * 2 * 3
    with pytest.raises(ValueError, match="other settings"):
        build_cache(CacheSpec(str(dataset), "unused", size=32, frames_per_clip=3, max_clips=6), a, rig=rig32)


def test_training_resumes_exactly(dataset: Path, tmp_path: Path, rig32: RigConfig) -> None:
    straight = train_composite(_settings(dataset, 6), tmp_path / "s", checkpoint_every=3, progress=False, rig=rig32)
    half = tmp_path / "r"
    assert (
        train_composite(_settings(dataset, 6), half, checkpoint_every=5, progress=False, rig=rig32, stop_after=3)
        is None
    )
    resumed = train_composite(_settings(dataset, 6), half, checkpoint_every=5, progress=False, rig=rig32)
    assert straight is not None and resumed is not None
    a, b = load_file(str(straight / "model.safetensors")), load_file(str(resumed / "model.safetensors"))
    assert a.keys() == b.keys()
    for k in a:
        np.testing.assert_array_equal(a[k], b[k], err_msg=k)
    model = load_world_model(straight)
    assert isinstance(model, CompositeWorldModel)
    log = [json.loads(line) for line in (tmp_path / "s" / "log.jsonl").read_text().splitlines()]
    assert any("validation" in e for e in log)
    with pytest.raises(ValueError, match="other settings"):
        train_composite(
            TrainSettings(**{**_settings(dataset, 6).__dict__, "lr": 1e-4}), half, progress=False, rig=rig32
        )


def test_the_loss_goes_down(dataset: Path, tmp_path: Path, rig32: RigConfig) -> None:
    s = TrainSettings(**{**_settings(dataset, 60).__dict__, "lr": 5e-3})
    train_composite(s, tmp_path / "l", checkpoint_every=60, validate_every=60, log_every=5, progress=False, rig=rig32)
    log = [json.loads(line) for line in (tmp_path / "l" / "log.jsonl").read_text().splitlines()]
    losses = [e["l1"] for e in log if "l1" in e]
    assert len(losses) == 12
    assert np.mean(losses[-3:]) < 0.9 * np.mean(losses[:3])
