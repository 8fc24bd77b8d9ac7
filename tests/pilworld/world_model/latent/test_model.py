"""The native PiL-World model (preset ``tiny``, 32×32, K = 3): the WorldModel contract, input errors,
the flow-matching loss, the history ablation, the ablation configs, checkpoints with LoRA adapters,
and the instruction encoder.

Before training the denoiser's output head is zero-initialised (adaLN-Zero), so the prediction would
ignore every condition; tests that need conditions to matter perturb the weights first.
"""

from __future__ import annotations

import dataclasses
import json
from pathlib import Path
from typing import Any

import numpy as np
import pytest
import torch
from safetensors.torch import load_file

from pilworld.world_model.base import PredictRequest, WorldModel, WorldModelBatch
from pilworld.world_model.latent.checkpoint import save_model
from pilworld.world_model.latent.config import WorldModelConfig, preset
from pilworld.world_model.latent.denoiser import Block
from pilworld.world_model.latent.lora import add_lora, save_adapter
from pilworld.world_model.latent.model import PilWorldModel
from pilworld.world_model.latent.text import InstructionEncoder, word_buckets
from pilworld.world_model.loader import load_world_model

K = 3
B = 2


def make_model(config: WorldModelConfig | None = None, seed: int = 0) -> PilWorldModel:
    """A tiny model whose output head is perturbed, so predictions depend on every condition."""
    torch.manual_seed(seed)
    model = PilWorldModel(config or preset("tiny", future=K))
    with torch.no_grad():
        torch.nn.init.normal_(model.denoiser.token_out.weight, std=0.05)
        torch.nn.init.normal_(model.denoiser.modulation_out.weight, std=0.05)
        for block in model.denoiser.blocks:  # open the adaLN-Zero gates, so tokens interact (action tokens)
            assert isinstance(block, Block)
            torch.nn.init.normal_(block.modulation.weight, std=0.05)
            torch.nn.init.normal_(block.modulation.bias, std=0.5)
    return model.eval()


def make_batch(model: PilWorldModel, seed: int = 0, size: int = B) -> WorldModelBatch:
    cfg = model.config
    V, Hh, H, W = len(cfg.views), cfg.history, cfg.height, cfg.width
    g = torch.Generator().manual_seed(seed)

    def img(*shape: int) -> torch.Tensor:
        return torch.randint(0, 256, shape, generator=g, dtype=torch.uint8)

    return WorldModelBatch(
        current=img(size, V, 3, H, W),
        history=img(size, V, Hh, 3, H, W),
        history_valid=torch.ones(size, Hh, dtype=torch.bool),
        control=img(size, cfg.future, 3, H, W),
        actions=torch.randn(size, cfg.future, cfg.action_dim, generator=g),
        instruction=["stack the red block"] * size,
    )


def request_args(model: PilWorldModel, seed: int = 0) -> dict[str, Any]:
    info = model.info
    rng = np.random.default_rng(seed)

    def img(*shape: int) -> np.ndarray:
        return rng.integers(0, 256, size=shape, dtype=np.uint8)

    return {
        "current": {v: img(info.height, info.width, 3) for v in info.views},
        "history": {v: img(info.history, info.height, info.width, 3) for v in info.views},
        "control": img(info.future, info.height, info.width, 3),
        "actions": rng.standard_normal((info.future, info.action_dim)),
        "instruction": "sort the blue cubes",
    }


@pytest.fixture(scope="module")
def model() -> PilWorldModel:
    return make_model()


# ---------------------------------------------------------------------- the WorldModel contract


def test_predict_batch_shape_and_dtype(model: PilWorldModel) -> None:
    assert isinstance(model, WorldModel)
    out = model.predict_batch(make_batch(model))
    assert out.dtype == torch.uint8
    assert tuple(out.shape) == (B, 3, K, 3, 32, 32)


def test_predict_request_matches_predict_batch(model: PilWorldModel) -> None:
    req = PredictRequest.build(model.info, **request_args(model))
    out = model.predict(req, seed=3)
    assert list(out) == list(model.info.views)
    for frames in out.values():
        assert frames.dtype == np.uint8 and frames.shape == (K, 32, 32, 3)
    batched = model.predict_batch(req.to_batch(model.info.views), seed=3)[0]  # [V, K, 3, H, W]
    for i, v in enumerate(model.info.views):
        np.testing.assert_array_equal(out[v], batched[i].permute(0, 2, 3, 1).numpy())


def test_history_none_repeats_current_as_invalid(model: PilWorldModel) -> None:
    args = request_args(model)
    args["history"] = None
    req = PredictRequest.build(model.info, **args)
    assert not req.history_valid.any()
    np.testing.assert_array_equal(req.history["cam_high"][-1], args["current"]["cam_high"])
    assert model.predict(req)["cam_high"].shape == (K, 32, 32, 3)


def test_seeded_sampling(model: PilWorldModel) -> None:
    batch = make_batch(model)
    a = model.predict_batch(batch, seed=1)
    assert torch.equal(a, model.predict_batch(batch, seed=1))
    assert not torch.equal(a, model.predict_batch(batch, seed=2))
    # More Euler steps integrate differently (the step count is honoured).
    assert not torch.equal(a, model.predict_batch(batch, seed=1, steps=3))


# ---------------------------------------------------------------------- input errors


def _drop_view(a: dict[str, Any]) -> None:
    del a["current"]["cam_left_wrist"]


def _rename_view(a: dict[str, Any]) -> None:
    a["history"]["cam_top"] = a["history"].pop("cam_right_wrist")


def _small_image(a: dict[str, Any]) -> None:
    a["current"]["cam_high"] = np.zeros((16, 16, 3), dtype=np.uint8)


def _float_image(a: dict[str, Any]) -> None:
    a["current"]["cam_high"] = a["current"]["cam_high"].astype(np.float32)


def _history_frames(a: dict[str, Any]) -> None:
    a["history"]["cam_high"] = a["history"]["cam_high"][:2]


def _control_frames(a: dict[str, Any]) -> None:
    a["control"] = a["control"][:1]


def _nan_action(a: dict[str, Any]) -> None:
    a["actions"][1, 4] = np.nan


def _action_shape(a: dict[str, Any]) -> None:
    a["actions"] = a["actions"][:, :7]


def _history_valid(a: dict[str, Any]) -> None:
    a["history_valid"] = [True, False]


@pytest.mark.parametrize(
    ("corrupt", "match"),
    [
        (_drop_view, r"current: views do not match .*missing \['cam_left_wrist'\]"),
        (_rename_view, r"history: views do not match .*unexpected \['cam_top'\]"),
        (_small_image, r"current\['cam_high'\]: expected shape \(32, 32, 3\), got \(16, 16, 3\)"),
        (_float_image, r"current\['cam_high'\]: expected uint8"),
        (_history_frames, r"history\['cam_high'\]: expected shape \(5, 32, 32, 3\)"),
        (_control_frames, r"control: expected shape \(3, 32, 32, 3\)"),
        (_nan_action, r"actions: non-finite value nan at index \(1, 4\)"),
        (_action_shape, r"actions: expected stride-aligned actions of shape \(3, 14\), got \(3, 7\)"),
        (_history_valid, r"history_valid: expected shape \(5,\)"),
    ],
)
def test_bad_request_raises(model: PilWorldModel, corrupt: Any, match: str) -> None:
    args = request_args(model)
    corrupt(args)
    with pytest.raises(ValueError, match=match):
        PredictRequest.build(model.info, **args)


@pytest.mark.parametrize("steps", [0, -1, True, 1.5])
def test_bad_steps_raise(model: PilWorldModel, steps: Any) -> None:
    with pytest.raises(ValueError, match="steps: expected an integer >= 1"):
        model.predict_batch(make_batch(model), steps=steps)


def test_bad_batch_raises(model: PilWorldModel) -> None:
    batch = make_batch(model)
    bad = dataclasses.replace(batch, control=batch.control[:, :2])
    with pytest.raises(ValueError, match=r"control: expected shape \(2, 3, 3, 32, 32\)"):
        model.predict_batch(bad)
    bad = dataclasses.replace(batch, actions=batch.actions.clone())
    bad.actions[0, 0, 0] = float("inf")
    with pytest.raises(ValueError, match="actions: contains non-finite values"):
        model.predict_batch(bad)
    with pytest.raises(ValueError, match="instruction: expected 2 strings"):
        model.predict_batch(dataclasses.replace(batch, instruction=["one"]))


# ---------------------------------------------------------------------- training objective


def test_flow_loss_decreases_on_a_fixed_batch() -> None:
    torch.manual_seed(0)
    model = PilWorldModel(preset("tiny", future=K)).train()
    batch = make_batch(model)
    with torch.no_grad():
        future = torch.randn(B, 3, K, 4, 4, 4)
        current = model.encode(batch.current)
        history = model.encode(batch.history)
    params = [p for p in model.denoiser.parameters()]
    opt = torch.optim.Adam(params, lr=1e-3)
    losses = []
    for _ in range(30):
        loss, logs = model.flow_loss(
            future,
            current,
            history,
            batch.history_valid,
            batch.control,
            batch.actions,
            batch.instruction,
            torch.Generator().manual_seed(0),  # the same noise every step: a fixed objective
        )
        assert logs["loss"] == pytest.approx(float(loss.detach())) and np.isfinite(logs["x0_mse"])
        opt.zero_grad()
        loss.backward()
        opt.step()
        losses.append(logs["loss"])
    assert losses[-1] < 0.8 * losses[0], losses
    # Only Ψ_θ was optimised: the VAE received no gradient (it is frozen in stage 1's denoiser phase).
    assert all(p.grad is None for p in model.vae.parameters())


# ---------------------------------------------------------------------- history ablation


def test_without_history_hides_history_and_restores_the_flag() -> None:
    model = make_model()
    with torch.no_grad():
        torch.nn.init.normal_(model.denoiser.token_in.weight, std=0.2)  # history channels matter
    batch = make_batch(model)
    full = model.predict_batch(batch, seed=0)
    ablated_view = model.without_history()
    ablated = ablated_view.predict_batch(batch, seed=0)
    assert not torch.equal(full, ablated)
    assert model.mask_history is False
    # Hiding the history is the same as a batch whose history frames are all flagged missing.
    hidden = dataclasses.replace(batch, history_valid=torch.zeros_like(batch.history_valid))
    assert torch.equal(ablated, model.predict_batch(hidden, seed=0))
    assert ablated_view.info == model.info
    out = ablated_view.predict(PredictRequest.build(model.info, **request_args(model)))
    assert out["cam_high"].shape == (K, 32, 32, 3)
    # The flag is restored after an error too.
    with pytest.raises(ValueError, match="steps"):
        ablated_view.predict_batch(batch, steps=0)
    assert model.mask_history is False


# ---------------------------------------------------------------------- ablation configs


def _with(**switches: bool) -> WorldModelConfig:
    base = preset("tiny", future=K)
    return base.replace(conditioning=dataclasses.replace(base.conditioning, **switches))


@pytest.mark.parametrize(
    "switches",
    [
        {},
        {"action_tokens": True},
        {"control_video": False, "action_tokens": True},
        {"history": False},
    ],
    ids=["default", "control+actions", "actions-only", "no-history"],
)
def test_ablation_configs_build_and_predict(switches: dict[str, bool]) -> None:
    model = make_model(_with(**switches))
    cond = model.config.conditioning
    assert hasattr(model.denoiser, "control_stem") == cond.control_video
    assert hasattr(model.denoiser, "action_in") == cond.action_tokens
    batch = make_batch(model)
    out = model.predict_batch(batch)
    assert tuple(out.shape) == (B, 3, K, 3, 32, 32)
    # The conditions a config uses change the prediction; the ones it drops do not.
    other_actions = dataclasses.replace(batch, actions=batch.actions + 1.0)
    assert torch.equal(out, model.predict_batch(other_actions)) != cond.action_tokens
    other_control = dataclasses.replace(batch, control=255 - batch.control)
    assert torch.equal(out, model.predict_batch(other_control)) != cond.control_video
    if not cond.history:
        other_history = dataclasses.replace(batch, history=255 - batch.history)
        assert torch.equal(out, model.predict_batch(other_history))


def test_no_control_video_and_no_action_tokens_is_rejected() -> None:
    with pytest.raises(ValueError, match="needs the control video, action tokens, or both"):
        _with(control_video=False, action_tokens=False)


# ---------------------------------------------------------------------- config


def test_config_round_trip() -> None:
    cfg = _with(history=False, action_tokens=True).replace(latent_mean=(0.1, 0.2, 0.3, 0.4), latent_std=(1.0,) * 4)
    assert WorldModelConfig.from_dict(cfg.to_dict()) == cfg
    assert WorldModelConfig.from_dict(json.loads(json.dumps(cfg.to_dict()))) == cfg  # lists back to tuples
    for name in ("tiny", "small", "base"):
        assert WorldModelConfig.from_dict(preset(name).to_dict()) == preset(name)


def test_config_errors() -> None:
    data = preset("tiny").to_dict()
    with pytest.raises(ValueError, match=r"unknown keys \['colour'\]"):
        WorldModelConfig.from_dict({**data, "colour": "red"})
    with pytest.raises(ValueError, match=r"unknown keys \['depthh'\] in 'denoiser'"):
        WorldModelConfig.from_dict({**data, "denoiser": {**data["denoiser"], "depthh": 3}})
    with pytest.raises(ValueError, match="must be divisible by 16"):
        preset("tiny", height=40)
    with pytest.raises(ValueError, match="must be divisible by 16"):
        preset("tiny", width=24)
    with pytest.raises(ValueError, match=r"preset: unknown 'huge'"):
        preset("huge")
    with pytest.raises(ValueError, match="latent_std: expected 4 values"):
        preset("tiny", latent_std=(1.0, 1.0))


# ---------------------------------------------------------------------- checkpoints and LoRA


def test_save_and_load_give_identical_predictions(model: PilWorldModel, tmp_path: Path) -> None:
    folder = save_model(model, tmp_path / "m")
    loaded = load_world_model(folder)
    assert loaded.config == model.config and not loaded.training
    batch = make_batch(model)
    assert torch.equal(model.predict_batch(batch, seed=4), loaded.predict_batch(batch, seed=4))


def test_latent_stats_are_saved_with_the_config(tmp_path: Path) -> None:
    model = make_model()
    model.set_latent_stats([0.5, -0.5, 0.0, 1.0], [2.0, 1.0, 0.5, 1.5])
    loaded = load_world_model(save_model(model, tmp_path / "m"))
    assert torch.equal(loaded.latent_mean, model.latent_mean) and torch.equal(loaded.latent_std, model.latent_std)
    batch = make_batch(model)
    assert torch.equal(model.predict_batch(batch), loaded.predict_batch(batch))


def test_float16_checkpoint_loads(model: PilWorldModel, tmp_path: Path) -> None:
    folder = save_model(model, tmp_path / "half", dtype=torch.float16)
    stored = load_file(str(folder / "model.safetensors"))
    assert all(v.dtype == torch.float16 for v in stored.values() if v.is_floating_point())
    loaded = load_world_model(folder)
    for name, p in loaded.state_dict().items():
        assert p.dtype == torch.float32
        assert torch.equal(p, model.state_dict()[name].half().float()), name
    out = loaded.predict_batch(make_batch(model))
    assert out.dtype == torch.uint8 and tuple(out.shape) == (B, 3, K, 3, 32, 32)


def test_missing_checkpoint_errors(tmp_path: Path) -> None:
    with pytest.raises(FileNotFoundError, match="not a world-model folder"):
        load_world_model(tmp_path / "nowhere")
    (tmp_path / "empty").mkdir()
    with pytest.raises(FileNotFoundError, match=r"config\.json"):
        load_world_model(tmp_path / "empty")


def test_lora_adapter_round_trip(tmp_path: Path) -> None:
    model = make_model()
    folder = save_model(model, tmp_path / "m")
    batch = make_batch(model)
    base_out = model.predict_batch(batch)
    trainable = add_lora(model, rank=2)
    assert trainable and all("lora_" in n for n in trainable)
    with torch.no_grad():
        for name, p in model.named_parameters():
            if "lora_" in name:
                # Perturb, then round to float16 as save_adapter stores it, so only merging differs.
                p.copy_((torch.randn_like(p) * 0.2).half().float())
    unmerged = model.predict_batch(batch)
    assert not torch.equal(unmerged, base_out)  # the adapter changes the prediction
    save_adapter(model, folder / "adapters" / "taskA", rank=2)

    merged = load_world_model(folder, adapter="taskA")
    diff = (merged.predict_batch(batch).int() - unmerged.int()).abs().max()
    assert int(diff) <= 1  # merged weights equal the unmerged sum up to float rounding
    assert not any(p.requires_grad for p in merged.parameters())
    # Without an adapter the folder still loads the base model.
    assert torch.equal(load_world_model(folder).predict_batch(batch), base_out)
    with pytest.raises(ValueError, match=r"adapter: 'taskB' not in .*available: \['taskA'\]"):
        load_world_model(folder, adapter="taskB")


def test_lora_rank_must_be_positive() -> None:
    with pytest.raises(ValueError, match="lora_rank"):
        add_lora(make_model(), rank=0)


# ---------------------------------------------------------------------- instruction encoder


def test_instruction_encoder() -> None:
    torch.manual_seed(0)
    enc = InstructionEncoder(buckets=256, width=16, out_width=32)
    a = enc(["stack the red block"])
    assert a.shape == (1, 32)
    assert torch.equal(a, enc(["stack the red block"]))
    assert torch.equal(a, enc(["Stack the RED block!"]))  # lower-cased words, punctuation ignored
    assert not torch.allclose(a, enc(["sort the blue cubes"]))
    assert not torch.allclose(a, enc(["block red the stack"]))  # word pairs keep some order
    empty = enc([""])
    assert empty.shape == (1, 32) and torch.isfinite(empty).all()
    both = enc(["stack the red block", "", "sort the blue cubes"])  # a batch mixes lengths
    assert torch.allclose(both[0], a[0], atol=1e-6) and torch.allclose(both[1], empty[0], atol=1e-6)


def test_word_buckets_are_stable() -> None:
    import zlib

    assert word_buckets("Stack blocks", 1000) == [
        zlib.crc32(b"stack") % 1000,
        zlib.crc32(b"blocks") % 1000,
        zlib.crc32(b"stack blocks") % 1000,
    ]
    assert word_buckets("", 1000) == [0] and word_buckets("!!", 7) == [0]


def test_export_casts_to_float16_and_gathers_adapters(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    from pilworld.cli.main import main
    from pilworld.world_model.loader import adapter_names

    base = make_model(seed=3)
    save_model(base, tmp_path / "s1")
    stage2 = make_model(seed=3)
    add_lora(stage2, 2)
    with torch.no_grad():
        for name, p in stage2.named_parameters():
            if "lora_B" in name:
                p.normal_(0, 0.05)
    save_adapter(stage2, tmp_path / "s2" / "adapters" / "taskA", 2)
    out = tmp_path / "shipped"
    assert main(["train", "export", str(tmp_path / "s1"), "--adapters", str(tmp_path / "s2"), "--out", str(out)]) == 0
    weights = load_file(str(out / "model.safetensors"))
    assert all(v.dtype == torch.float16 for v in weights.values() if v.is_floating_point())
    assert adapter_names(out) == ["taskA"]
    merged = load_world_model(out, adapter="taskA")
    plain = load_world_model(out)
    batch = make_batch(plain, seed=1)
    assert not torch.equal(merged.predict_batch(batch), plain.predict_batch(batch))
    capsys.readouterr()
    # --debug prints the traceback and keeps the documented exit status (2: bad input).
    rc = main(["--debug", "train", "export", str(tmp_path / "s1"), "--adapters", str(tmp_path), "--out", str(out)])
    assert rc == 2 and "no LoRA adapter" in capsys.readouterr().err


def test_legacy_residual_decoding_key_maps_to_the_gate() -> None:
    data = preset("tiny").to_dict()
    del data["residual_gate"]
    assert WorldModelConfig.from_dict({**data, "residual_decoding": False}).residual_gate == 0.0
    assert WorldModelConfig.from_dict({**data, "residual_decoding": True}).residual_gate == preset("tiny").residual_gate


def test_gated_residual_decoding_keeps_unchanged_pixels(model: PilWorldModel) -> None:
    """Future latents equal to the current ones decode to the current frame exactly (the gate is fully open)."""
    batch = make_batch(model)
    with torch.no_grad():
        z0 = model.encode(batch.current)
        same = z0[:, :, None].expand(-1, -1, model.config.future, -1, -1, -1).contiguous()
        frames = model.render_future(same, z0, batch.current)
    assert torch.equal(frames, batch.current[:, :, None].expand_as(frames))
