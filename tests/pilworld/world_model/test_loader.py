"""One loader for every world-model format (pilworld.world_model.loader) and the optional capabilities
a caller queries with isinstance (pilworld.world_model.base)."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import numpy as np
import pytest

from pilworld.world_model import DEFAULT_CHECKPOINT
from pilworld.world_model.base import (
    FrozenWorldModel,
    HistoryAblation,
    PredictRequest,
    RigBound,
    StatefulRollout,
    StatePrediction,
    WorldModel,
    WorldModelInfo,
)
from pilworld.world_model.latent.checkpoint import save_model
from pilworld.world_model.latent.config import preset
from pilworld.world_model.latent.model import PilWorldModel
from pilworld.world_model.loader import FORMATS, adapter_names, format_of, load_world_model

WAN_INFO = WorldModelInfo(views=("head", "left_wrist"), height=16, width=16, future=3, history=2)


def _request(info: WorldModelInfo, seed: int = 0) -> PredictRequest:
    rng = np.random.default_rng(seed)

    def img(*shape: int) -> np.ndarray:
        return rng.integers(0, 256, (*shape, 3), dtype=np.uint8)

    return PredictRequest.build(
        info,
        current={v: img(info.height, info.width) for v in info.views},
        history={v: img(info.history, info.height, info.width) for v in info.views},
        control=img(info.future, info.height, info.width),
        actions=np.zeros((info.future, info.action_dim), np.float32),
        instruction="put the cube in the bowl",
    )


def test_the_shipped_model_is_v2_and_offers_its_capabilities() -> None:
    model = load_world_model(DEFAULT_CHECKPOINT)
    assert format_of(DEFAULT_CHECKPOINT).name == "pilworld-composite-world-model/1"
    assert isinstance(model, WorldModel)
    assert isinstance(model, RigBound) and isinstance(model, StatefulRollout) and isinstance(model, StatePrediction)
    assert not isinstance(model, HistoryAblation)
    assert adapter_names(DEFAULT_CHECKPOINT) == []
    with pytest.raises(ValueError, match=r"v2 \(composite\) world model, which has no task adapters"):
        load_world_model(DEFAULT_CHECKPOINT, adapter="sort_cubes")


def test_a_v1_folder_loads_through_the_same_loader(tmp_path: Path) -> None:
    folder = save_model(PilWorldModel(preset("tiny", future=3)), tmp_path / "v1")
    model = load_world_model(folder)
    assert isinstance(model, PilWorldModel) and isinstance(model, HistoryAblation)
    assert not isinstance(model, RigBound) and not isinstance(model, StatefulRollout)
    assert isinstance(model.without_history(), WorldModel)
    with pytest.raises(ValueError, match="adapter: 'nope' not in"):
        load_world_model(folder, adapter="nope")


def test_the_frozen_baseline_has_no_optional_capability() -> None:
    model = FrozenWorldModel(WAN_INFO)
    assert isinstance(model, WorldModel)
    assert not any(isinstance(model, c) for c in (RigBound, StatefulRollout, StatePrediction, HistoryAblation))


def test_a_wan_folder_loads_by_its_format_and_a_stock_one_with_the_rigs_info(tmp_path: Path) -> None:
    pytest.importorskip("diffusers")
    from pilworld.world_model.wan.backend import WanWorldModel

    original = WanWorldModel.tiny_random(WAN_INFO)
    folder = tmp_path / "wan"
    original.save_pretrained(folder)
    assert format_of(folder).name == "pilworld-wan2.1/1"
    model = load_world_model(folder)
    assert isinstance(model, WanWorldModel) and model.info == WAN_INFO and model.default_steps == 2
    request = _request(WAN_INFO)
    for view, frames in original.predict(request, seed=3).items():
        np.testing.assert_array_equal(model.predict(request, seed=3)[view], frames)

    stock = tmp_path / "stock"
    shutil.copytree(folder, stock)
    (stock / "config.json").unlink()  # a stock diffusers folder: no views or sizes of ours
    assert format_of(stock).name == "wan2.1-diffusers"
    with pytest.raises(ValueError, match=r"stock Wan2\.1 folder does not say which views"):
        load_world_model(stock)
    assert load_world_model(stock, info=WAN_INFO).info == WAN_INFO


def test_folders_that_are_no_world_model_get_one_line(tmp_path: Path) -> None:
    with pytest.raises(FileNotFoundError, match="not a world-model folder"):
        load_world_model(tmp_path / "absent")
    with pytest.raises(FileNotFoundError, match=r"no readable config\.json naming a format"):
        load_world_model(tmp_path)
    (tmp_path / "config.json").write_text(json.dumps({"format": "someone-elses/3", "config": {}}))
    with pytest.raises(ValueError, match="format 'someone-elses/3' is not a world-model format"):
        load_world_model(tmp_path)
    (tmp_path / "config.json").write_text("{not json")
    with pytest.raises(FileNotFoundError, match=r"no readable config\.json"):
        load_world_model(tmp_path)


def test_every_format_is_listed_once() -> None:
    assert len(FORMATS) == 3 and all(name == f.name for name, f in FORMATS.items())
