"""The Wan2.1 backend on CPU with tiny random weights (diffusers' own test sizes); skipped without diffusers."""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import pytest
import torch

pytest.importorskip("diffusers")

from pilworld.world_model.base import PredictRequest, WorldModel, WorldModelBatch, WorldModelInfo
from pilworld.world_model.wan.backend import HashedInstructionEncoder, WanWorldModel, _diffusers, wan_frame_count

INFO = WorldModelInfo(views=("head", "left_wrist"), height=16, width=16, future=3, history=2)


def make_batch(info: WorldModelInfo, size: int = 1, seed: int = 0) -> WorldModelBatch:
    g = torch.Generator().manual_seed(seed)
    V, K, Hh, H, W = len(info.views), info.future, info.history, info.height, info.width

    def img(*shape: int) -> torch.Tensor:
        return torch.randint(0, 256, shape, generator=g, dtype=torch.uint8)

    valid = torch.ones(size, Hh, dtype=torch.bool)
    valid[:, :1] = False  # the oldest history frame precedes the episode
    return WorldModelBatch(
        current=img(size, V, 3, H, W),
        history=img(size, V, Hh, 3, H, W),
        history_valid=valid,
        control=img(size, K, 3, H, W),
        actions=torch.zeros(size, K, info.action_dim),
        instruction=["put the red cube in the bowl"] * size,
    )


@pytest.fixture(scope="module")
def model() -> WanWorldModel:
    return WanWorldModel.tiny_random(INFO)


@pytest.mark.parametrize(("n", "expected"), [(1, (1, 0)), (4, (5, 1)), (5, (5, 0)), (6, (9, 3)), (16, (17, 1))])
def test_frame_count_pads_to_4k_plus_1(n: int, expected: tuple[int, int]) -> None:
    assert wan_frame_count(n) == expected


@pytest.mark.parametrize("n", [0, -3, True, 2.5])
def test_frame_count_rejects_bad_counts(n: object) -> None:
    with pytest.raises(ValueError, match="n: expected a frame count"):
        wan_frame_count(n)  # type: ignore[arg-type]


def test_predicts_uint8_segment_of_the_right_shape(model: WanWorldModel) -> None:
    assert isinstance(model, WorldModel)
    out = model.predict_batch(make_batch(INFO, size=2))
    assert out.shape == (2, 2, INFO.future, 3, 16, 16)
    assert out.dtype == torch.uint8


def test_predict_one_request(model: WanWorldModel) -> None:
    rng = np.random.default_rng(0)
    current = {v: rng.integers(0, 256, (16, 16, 3), dtype=np.uint8) for v in INFO.views}
    control = np.zeros((INFO.future, 16, 16, 3), dtype=np.uint8)
    req = PredictRequest.build(
        INFO, current=current, history=None, control=control, actions=np.zeros((3, 14)), instruction="stack"
    )
    out = model.predict(req)
    assert set(out) == set(INFO.views)
    assert all(v.shape == (INFO.future, 16, 16, 3) and v.dtype == np.uint8 for v in out.values())


@pytest.mark.parametrize(
    ("views", "size", "future", "history", "latents_pad"),
    [(("head", "left", "right"), 32, 5, 2, (2, 3)), (("head",), 16, 15, 0, (4, 1))],
)
def test_frame_padding_and_view_counts(
    views: tuple[str, ...], size: int, future: int, history: int, latents_pad: tuple[int, int]
) -> None:
    # K=5: [current, f1..f5] = 6 frames -> 9 = 4*2+1; K=15 (the paper's): 16 -> 17 = 4*4+1.
    info = WorldModelInfo(views=views, height=size, width=size, future=future, history=history)
    m = WanWorldModel.tiny_random(info, default_steps=1)
    assert (m.n_future, m.pad) == latents_pad
    assert m.predict_batch(make_batch(info)).shape == (1, len(views), future, 3, size, size)


def test_seeded_determinism(model: WanWorldModel) -> None:
    batch = make_batch(INFO)
    a = model.predict_batch(batch, seed=3)
    assert torch.equal(a, model.predict_batch(batch, seed=3))
    assert not torch.equal(a, model.predict_batch(batch, seed=4))


def test_conditioning_layout(model: WanWorldModel) -> None:
    # Tiny random VAE latents barely depend on the pixels, so check where each input lands, not its effect.
    context, cond, current = model._conditioning(make_batch(INFO))
    n_ctx, w = INFO.history + 1, model.lat_w
    assert context.shape == (1, 16, n_ctx, model.lat_h, 2 * w)
    assert cond.shape == (1, 1 + 16, n_ctx + model.n_future, model.lat_h, 2 * w)
    assert current.shape == (2, 16, 1, model.lat_h, w)
    assert cond[0, 0, :, 0, 0].tolist() == [0.0, 1.0, 1.0, 0.0]  # invalid history, valid history, current, future
    assert torch.count_nonzero(context[:, :, 0]) == 0  # the invalid history frame is blanked
    assert torch.equal(context[:, :, -1, :, :w], current[0, :, 0][None])  # current latent, head tile
    control = cond[:, 1:]
    assert torch.count_nonzero(control[:, :, :n_ctx]) == 0  # no control at context frames
    assert torch.count_nonzero(control[:, :, n_ctx:, :, w:]) == 0  # nor outside the head view's tile
    assert torch.count_nonzero(control[:, :, n_ctx:, :, :w]) > 0


def test_bad_inputs_raise(model: WanWorldModel) -> None:
    wrong_size = make_batch(WorldModelInfo(views=INFO.views, height=32, width=32, future=3, history=2))
    with pytest.raises(ValueError, match="current: expected shape"):
        model.predict_batch(wrong_size)
    nan = make_batch(INFO)
    nan.actions[0, 1, 2] = float("nan")
    with pytest.raises(ValueError, match="actions"):
        model.predict_batch(nan)
    with pytest.raises(ValueError, match="steps"):
        model.predict_batch(make_batch(INFO), steps=0)


def test_image_size_must_fit_vae_and_patch() -> None:
    with pytest.raises(ValueError, match=r"width: expected a multiple of 16.*got 24"):
        WanWorldModel.tiny_random(WorldModelInfo(views=("head",), height=16, width=24, future=3, history=1))


def test_instruction_encoder_is_deterministic_and_zero_padded() -> None:
    enc = HashedInstructionEncoder(32, buckets=64, dim=8, max_tokens=6)
    a = enc(["Pick the cube", "pick THE cube!", "open drawer"])
    assert a.shape == (3, 6, 32)
    assert torch.equal(a[0], a[1])  # case and punctuation do not matter
    assert not torch.equal(a[0], a[2])
    assert torch.count_nonzero(a[0, 3:]) == 0  # three words, then padding
    again = HashedInstructionEncoder(32, buckets=64, dim=8, max_tokens=6)  # seeded construction
    assert torch.equal(a[:1], again(["pick the cube"]))


def test_from_pretrained_round_trip(model: WanWorldModel, tmp_path: Path) -> None:
    model.save_pretrained(tmp_path / "wan")
    loaded = WanWorldModel.from_pretrained(tmp_path / "wan", INFO, default_steps=model.default_steps)
    batch = make_batch(INFO)
    assert loaded.flow_shift == model.flow_shift
    assert torch.equal(loaded.predict_batch(batch, seed=1), model.predict_batch(batch, seed=1))


def test_from_pretrained_plain_diffusers_subfolders(model: WanWorldModel, tmp_path: Path) -> None:
    model.transformer.save_pretrained(str(tmp_path / "transformer"))
    model.vae.save_pretrained(str(tmp_path / "vae"))
    loaded = WanWorldModel.from_pretrained(tmp_path, INFO, default_steps=1)  # default instruction encoder
    assert loaded.predict_batch(make_batch(INFO)).shape == (1, 2, 3, 3, 16, 16)


def test_from_pretrained_widens_a_stock_t2v_transformer(model: WanWorldModel, tmp_path: Path) -> None:
    t2v = _diffusers().WanTransformer3DModel(
        num_attention_heads=2,
        attention_head_dim=12,
        in_channels=16,
        out_channels=16,
        text_dim=32,
        ffn_dim=32,
        num_layers=1,
        rope_max_seq_len=32,
    )
    t2v.save_pretrained(str(tmp_path / "transformer"))
    model.vae.save_pretrained(str(tmp_path / "vae"))
    loaded = WanWorldModel.from_pretrained(tmp_path, INFO, default_steps=1)
    assert loaded.transformer.config["in_channels"] == 33
    weight = loaded.transformer.patch_embedding.weight
    assert torch.equal(weight[:, :16], t2v.patch_embedding.weight) and torch.count_nonzero(weight[:, 16:]) == 0
    assert loaded.predict_batch(make_batch(INFO)).shape == (1, 2, 3, 3, 16, 16)


def test_from_pretrained_missing_folder_or_subfolder(model: WanWorldModel, tmp_path: Path) -> None:
    with pytest.raises(FileNotFoundError, match="does not exist"):
        WanWorldModel.from_pretrained(tmp_path / "nope", INFO)
    model.transformer.save_pretrained(str(tmp_path / "transformer"))
    with pytest.raises(FileNotFoundError, match=r"vae.*transformer/ and vae/"):
        WanWorldModel.from_pretrained(tmp_path, INFO)


def test_missing_diffusers_names_the_extra(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setitem(sys.modules, "diffusers", None)
    with pytest.raises(ImportError, match=r"pilworld\[wan\]"):
        _diffusers()
