"""ResizedWorldModel: a 32×32 model seen at the rig's size (inputs area-resized down, predictions
bilinear-resized up), ``upsample_images``, and ``resize=True`` in the paired runner's ``load_model``.
"""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np
import pytest
import torch
from numpy.typing import NDArray

from pilworld.config.rig import RigConfig
from pilworld.data.reader import EpisodeStore
from pilworld.paired import PairedConfig, paired_run
from pilworld.paired.runner import load_model
from pilworld.types import ChunkSpec
from pilworld.world_model.base import PredictRequest, WorldModel, WorldModelBatch, WorldModelInfo, predict_one
from pilworld.world_model.batching import resize_images
from pilworld.world_model.latent.checkpoint import save_model
from pilworld.world_model.latent.config import preset
from pilworld.world_model.latent.model import HistoryAblated, PilWorldModel
from pilworld.world_model.resized import ResizedWorldModel, upsample_images

SIM = "configs/rig/sim_dual_ur5e.yaml"
K = 3
B = 2
SIZE = 64


def _model(future: int = K) -> PilWorldModel:
    """The tiny preset (32×32) with a perturbed output head, so its predictions are not all the input."""
    torch.manual_seed(0)
    model = PilWorldModel(preset("tiny", future=future))
    with torch.no_grad():
        torch.nn.init.normal_(model.denoiser.token_out.weight, std=0.05)
    return model.eval()


def _batch(info: WorldModelInfo, height: int, width: int, seed: int = 0) -> WorldModelBatch:
    g = torch.Generator().manual_seed(seed)
    V, Hh = len(info.views), info.history

    def img(*shape: int) -> torch.Tensor:
        return torch.randint(0, 256, shape, generator=g, dtype=torch.uint8)

    return WorldModelBatch(
        current=img(B, V, 3, height, width),
        history=img(B, V, Hh, 3, height, width),
        history_valid=torch.tensor([[True] * Hh, [False] * Hh]),
        control=img(B, info.future, 3, height, width),
        actions=torch.randn(B, info.future, info.action_dim, generator=g),
        instruction=["sort the cubes", "stack the bowls"],
    )


@pytest.fixture(scope="module")
def tiny() -> PilWorldModel:
    return _model()


class _Recorder:
    """A stand-in 32×32 model that records what it was given and returns its current frames, K times."""

    def __init__(self, info: WorldModelInfo) -> None:
        self._info = info
        self.calls: list[tuple[WorldModelBatch, int | None, int]] = []

    @property
    def info(self) -> WorldModelInfo:
        return self._info

    def predict_batch(self, batch: WorldModelBatch, *, steps: int | None = None, seed: int = 0) -> torch.Tensor:
        batch.check(self._info)
        self.calls.append((batch, steps, seed))
        return batch.current[:, :, None].expand(-1, -1, self._info.future, -1, -1, -1).clone()

    def predict(
        self, request: PredictRequest, *, steps: int | None = None, seed: int = 0
    ) -> dict[str, NDArray[np.uint8]]:
        return predict_one(self, request, steps=steps, seed=seed)


def test_info_reports_the_outer_size(tiny: PilWorldModel) -> None:
    wrapped = ResizedWorldModel(tiny, height=SIZE, width=SIZE)
    assert isinstance(wrapped, WorldModel)
    assert (wrapped.info.height, wrapped.info.width) == (SIZE, SIZE)
    assert wrapped.info == dataclasses.replace(tiny.info, height=SIZE, width=SIZE)
    assert wrapped.native_size == (32, 32)
    assert (tiny.info.height, tiny.info.width) == (32, 32)  # the wrapped model is left alone
    with pytest.raises(ValueError, match="size"):
        ResizedWorldModel(tiny, height=0, width=SIZE)


def test_predict_batch_is_the_small_prediction_upsampled(tiny: PilWorldModel) -> None:
    wrapped = ResizedWorldModel(tiny, height=SIZE, width=SIZE)
    batch = _batch(wrapped.info, SIZE, SIZE)
    out = wrapped.predict_batch(batch, seed=4)
    assert out.dtype == torch.uint8
    assert tuple(out.shape) == (B, 3, K, 3, SIZE, SIZE)
    small = WorldModelBatch(
        current=resize_images(batch.current, 32, 32),
        history=resize_images(batch.history, 32, 32),
        history_valid=batch.history_valid,
        control=resize_images(batch.control, 32, 32),
        actions=batch.actions,
        instruction=batch.instruction,
    )
    expected = upsample_images(tiny.predict_batch(small, seed=4), SIZE, SIZE)
    assert torch.equal(out, expected)
    assert torch.equal(out, wrapped.predict_batch(batch, seed=4))  # seeded
    assert not torch.equal(out, wrapped.predict_batch(batch, seed=5))


def test_a_batch_at_another_size_is_refused(tiny: PilWorldModel) -> None:
    wrapped = ResizedWorldModel(tiny, height=SIZE, width=SIZE)
    with pytest.raises(ValueError, match=r"current: expected shape \(2, 3, 3, 64, 64\)"):
        wrapped.predict_batch(_batch(wrapped.info, 32, 32))
    with pytest.raises(ValueError, match="current"):
        wrapped.predict_batch(_batch(wrapped.info, SIZE, 48))


def test_inputs_reach_the_model_area_resized_and_the_rest_unchanged() -> None:
    info = WorldModelInfo(views=("cam_high", "cam_left_wrist"), height=32, width=32, future=K, history=2)
    inner = _Recorder(info)
    wrapped = ResizedWorldModel(inner, height=SIZE, width=SIZE)
    batch = _batch(wrapped.info, SIZE, SIZE, seed=1)
    out = wrapped.predict_batch(batch, steps=3, seed=7)
    (seen, steps, seed) = inner.calls[0]
    assert (steps, seed) == (3, 7)
    for name in ("current", "history", "control"):
        x = getattr(seen, name)
        assert tuple(x.shape[-2:]) == (32, 32), name
        assert torch.equal(x, resize_images(getattr(batch, name), 32, 32)), name
    # A 2×2 area mean of the first current pixel block.
    block = batch.current[0, 0, :, :2, :2].float().mean(dim=(1, 2)).round().to(torch.uint8)
    assert torch.equal(seen.current[0, 0, :, 0, 0], block)
    assert torch.equal(seen.history_valid, batch.history_valid)
    assert torch.equal(seen.actions, batch.actions)
    assert seen.instruction == batch.instruction
    assert tuple(out.shape) == (B, 2, K, 3, SIZE, SIZE)


def test_predict_returns_hwc_frames_at_the_outer_size(tiny: PilWorldModel) -> None:
    wrapped = ResizedWorldModel(tiny, height=SIZE, width=SIZE)
    info = wrapped.info
    rng = np.random.default_rng(0)
    req = PredictRequest.build(
        info,
        current={v: rng.integers(0, 256, (SIZE, SIZE, 3), dtype=np.uint8) for v in info.views},
        history={v: rng.integers(0, 256, (info.history, SIZE, SIZE, 3), dtype=np.uint8) for v in info.views},
        control=rng.integers(0, 256, (K, SIZE, SIZE, 3), dtype=np.uint8),
        actions=rng.standard_normal((K, info.action_dim)),
        instruction="sort the cubes",
    )
    out = wrapped.predict(req, seed=2)
    assert list(out) == list(info.views)
    batched = wrapped.predict_batch(req.to_batch(info.views), seed=2)[0]
    for i, v in enumerate(info.views):
        assert out[v].dtype == np.uint8 and out[v].shape == (K, SIZE, SIZE, 3)
        np.testing.assert_array_equal(out[v], batched[i].permute(0, 2, 3, 1).numpy())


def test_upsample_images() -> None:
    """Identity at the same size; bilinear otherwise, uint8, leading dimensions kept, flat stays flat."""
    x = torch.randint(0, 256, (2, 3, 4, 3, 16, 16), dtype=torch.uint8)
    assert upsample_images(x, 16, 16) is x
    up = upsample_images(x, 32, 48)
    assert up.dtype == torch.uint8 and tuple(up.shape) == (2, 3, 4, 3, 32, 48)
    # Every output pixel lies between the extremes of the source image it came from.
    assert torch.all(up.amax(dim=(-2, -1)) <= x.amax(dim=(-2, -1)))
    assert torch.all(up.amin(dim=(-2, -1)) >= x.amin(dim=(-2, -1)))
    flat = torch.full((1, 3, 8, 8), 200, dtype=torch.uint8)
    flat[:, 1] = 17
    up_flat = upsample_images(flat, 24, 24)
    assert torch.all(up_flat[:, 0] == 200) and torch.all(up_flat[:, 1] == 17)
    # Up then area-down by the same factor returns the image closely (a 2× bilinear round trip).
    smooth = torch.linspace(0, 255, 16).round().to(torch.uint8).expand(1, 3, 16, 16).contiguous()
    back = resize_images(upsample_images(smooth, 32, 32), 16, 16)
    assert (back.int() - smooth.int()).abs().max().item() <= 8


def test_load_model_resizes_a_model_of_another_size(tmp_path: Path) -> None:
    """resize=True wraps a 32×32 model folder for the 128×128 simulated rig; without it, a clear error."""
    folder = save_model(_model(future=ChunkSpec().frames), tmp_path / "tiny32")
    rig = RigConfig.load(SIM)
    kw: dict[str, object] = {
        "rig": SIM,
        "task": "sort_cubes",
        "checkpoints": ["scripted_step_30k"],
        "subtasks": 1,
        "out": str(tmp_path / "run"),
        "world_model": str(folder),
        "spec": ChunkSpec(rounds=1),
    }
    with pytest.raises(ValueError, match=r"works at 32x32.*128x128.*resize=True"):
        load_model(PairedConfig(**kw), rig, "sort_cubes")  # type: ignore[arg-type]
    model, adapter = load_model(PairedConfig(**kw, resize=True), rig, "sort_cubes")  # type: ignore[arg-type]
    assert adapter is None
    assert isinstance(model, ResizedWorldModel) and isinstance(model.model, PilWorldModel)
    assert (model.info.width, model.info.height) == (128, 128) and model.native_size == (32, 32)
    ablated, _ = load_model(PairedConfig(**kw, resize=True, history=False), rig, "sort_cubes")  # type: ignore[arg-type]
    assert isinstance(ablated, ResizedWorldModel) and isinstance(ablated.model, HistoryAblated)

    summary = paired_run(PairedConfig(**kw, resize=True), progress=False)  # type: ignore[arg-type]
    assert summary["branches_run"] == 2
    store = EpisodeStore(tmp_path / "run")
    imagined = store.load(0)
    assert imagined.origin == "imagined" and imagined.extra["world_model"] == str(folder)
    for v, frames in imagined.images.items():
        assert frames.shape[1:] == (128, 128, 3), v
