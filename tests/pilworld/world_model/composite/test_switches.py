"""The equal-budget variants of world model v2 (docs/RESULTS.md §1): what each switch changes, in training
and at inference."""

from __future__ import annotations

import dataclasses
import json
from pathlib import Path

import numpy as np
import pytest
import torch

from pilworld.config.rig import RigConfig
from pilworld.types import ARM_LAYOUT, ChunkSpec
from pilworld.world_model.base import PredictRequest
from pilworld.world_model.composite.cache import BASE_CHANNELS, CacheSpec, build_extras, has_extras
from pilworld.world_model.composite.checkpoint import save_composite
from pilworld.world_model.composite.model import CompositeConfig, CompositeWorldModel, blend, blend_bytes
from pilworld.world_model.composite.net import CANDIDATES, RobotPainter
from pilworld.world_model.composite.switches import Switches
from pilworld.world_model.composite.train import TrainSettings, _successful, train_composite
from pilworld.world_model.loader import load_world_model

from ..training.synthetic_data import write_dataset
from .test_model import _request as model_request

SPEC = ChunkSpec()
LEFT_ARM, _ = ARM_LAYOUT["left"]


@pytest.fixture(scope="module")
def dataset(tmp_path_factory: pytest.TempPathFactory) -> Path:
    with pytest.MonkeyPatch.context() as mp:
        mp.setenv("PILWORLD_CACHE", str(tmp_path_factory.mktemp("clip_cache")))
        return write_dataset(tmp_path_factory.mktemp("v2v") / "ds")


def _base(n: int = 6, s: int = 16) -> torch.Tensor:
    g = torch.Generator().manual_seed(0)
    x = torch.randint(0, 256, (n, BASE_CHANNELS, s, s), dtype=torch.uint8, generator=g)
    for c in (3, 10, 14, 24, 25):
        x[:, c] = torch.where(torch.rand(n, s, s, generator=g) < 0.5, 255, 0).to(torch.uint8)
    return x


def test_invalid_switches_are_refused_naming_the_setting() -> None:
    with pytest.raises(ValueError, match="control: expected one of"):
        Switches(control="video")
    with pytest.raises(ValueError, match="paste: the robot is pasted from its render"):
        Switches(control="markers")  # paste defaults to True, and markers have no render
    with pytest.raises(ValueError, match="unknown keys"):
        Switches.from_dict({"control": "render", "colour": 1})
    assert Switches.from_dict(None) == Switches() and Switches().shipped


def test_each_switch_changes_only_its_channels() -> None:
    x = _base()
    assert Switches().apply(x) is x  # the shipped model: untouched, no copy
    render = Switches(control="render").apply(x)
    assert torch.equal(render[:, 0:3], x[:, 4:7]) and bool((render[:, 3] == 255).all())  # the current frame, unwarped
    assert torch.equal(render[:, 4:], x[:, 4:])
    markers = Switches(control="markers", paste=False).apply(x)
    assert bool((markers[:, 15:21] == 0).all()) and torch.equal(markers[:, 21:], x[:, 21:])
    no_history = Switches(history=False).apply(x)
    assert bool((no_history[:, 21:25] == 0).all())
    assert torch.equal(no_history[:, :21], x[:, :21]) and torch.equal(no_history[:, 25], x[:, 25])
    no_hands = Switches(hands=False).apply(x)
    assert bool((no_hands[:, 25] == 255).all()) and torch.equal(no_hands[:, :25], x[:, :25])
    assert torch.equal(x, _base())  # the input itself is never modified


def test_without_paste_the_robots_pixels_come_from_the_gates() -> None:
    x = _base(n=3)
    x[:, 15:19] = 0
    x[:, 15, 4:8, 4:8] = 255  # a left-arm patch
    scal = torch.zeros(3, 8)
    scal[:, 5] = torch.arange(3)
    gates = torch.full((3, len(CANDIDATES), 4, 4), -50.0)
    gates[:, CANDIDATES.index("generated")] = 50.0
    generated = torch.full((3, 3, 4, 4), 0.25)
    painter, plate = RobotPainter(), torch.zeros(3, 16, 16)
    pasted = blend_bytes(x, scal, gates, generated, painter, plate)
    soft = blend_bytes(x, scal, gates, generated, painter, plate, paste=False)
    want = round(0.25 * 255)
    assert bool((soft[:, :, 4:8, 4:8] == want).all())  # the gated fill, not the painter
    assert not bool((pasted[:, :, 4:8, 4:8] == want).all())
    outside = torch.ones(16, 16, dtype=torch.bool)
    outside[4:8, 4:8] = False
    assert torch.equal(soft[:, :, outside], pasted[:, :, outside])
    float_soft = blend(x.float() / 255.0, scal, gates, generated, painter, plate, paste=False)
    assert ((float_soft.clamp(0, 1) * 255).round().to(torch.uint8).int() - soft.int()).abs().max() <= 1


def _request(model: CompositeWorldModel, seed: int = 0) -> PredictRequest:
    """test_model's request, with a random control video (the markers variant reads it)."""
    rng = np.random.default_rng(seed)
    control = rng.integers(0, 255, (SPEC.frames, 32, 32, 3), dtype=np.uint8)
    return dataclasses.replace(model_request(model), control=control)


@pytest.mark.parametrize(
    "switches",
    [
        Switches(control="markers", paste=False, history=False, hands=False),
        Switches(control="none", paste=False, history=False, hands=False, action_tokens=True),
        Switches(action_tokens=True),
    ],
    ids=["paper_gamma", "ctrl_world", "tokens"],
)
def test_variants_with_extra_inputs_see_them_and_round_trip(
    switches: Switches, rig32: RigConfig, tmp_path: Path
) -> None:
    torch.manual_seed(0)
    model = CompositeWorldModel(CompositeConfig(image_size=32, work_size=8, switches=switches), rig32).eval()
    assert model.net.in_channels == 36 + switches.extra_channels
    req = _request(model)
    frames, states = model.predict_with_state(req)
    assert frames["cam_high"].shape == (SPEC.frames, 32, 32, 3) and states.shape == (SPEC.frames, 14)
    # the extra inputs reach the network: another control video (markers) or other actions (tokens) change the output
    other = _request(model, seed=1)
    other = PredictRequest.build(
        model.info,
        current=dict(req.current),
        history=None,
        control=other.control if switches.markers else req.control,
        actions=req.actions + (0.2 if switches.action_tokens else 0.0) * (np.arange(14) == 0),
        instruction=req.instruction,
        state=req.state,
    )
    inp = model._variant_inputs(req, 8)
    inp2 = model._variant_inputs(other, 8)
    changed = [a is not None and not torch.equal(a, b) for a, b in zip(inp, inp2, strict=True) if b is not None]
    assert changed and all(changed)
    folder = save_composite(model, tmp_path / "v")
    assert json.loads((folder / "config.json").read_text())["config"]["switches"] == switches.to_dict()
    again = load_world_model(folder)
    assert isinstance(again, CompositeWorldModel) and again.switches == switches
    again.bind_rig(rig32)
    np.testing.assert_array_equal(again.predict(req)["cam_high"], frames["cam_high"])


def test_the_shipped_weights_load_as_the_shipped_recipe() -> None:
    model = load_world_model("pilworld/world_model/weights/sim_composite")
    assert isinstance(model, CompositeWorldModel) and model.switches.shipped


def test_variant_training_shares_the_cache_and_adds_the_extras(dataset: Path, tmp_path: Path, rig32: RigConfig) -> None:
    base = dict(
        data=str(dataset), steps=4, batch=6, width=8, work_size=8, cache_size=32, max_clips=12, frames_per_clip=2
    )
    cache = tmp_path / "cache"
    shipped = train_composite(TrainSettings(**base), tmp_path / "a", progress=False, rig=rig32, cache_dir=cache)  # type: ignore[arg-type]
    assert shipped is not None and not has_extras(cache)
    sw = Switches(control="markers", paste=False, action_tokens=True)
    out = train_composite(
        TrainSettings(**base, switches=sw),  # type: ignore[arg-type]
        tmp_path / "b",
        progress=False,
        rig=rig32,
        cache_dir=cache,
    )
    assert out is not None and has_extras(cache) and not (tmp_path / "b" / "cache").exists()
    markers, actions = np.load(cache / "markers.npy"), np.load(cache / "actions.npy")
    per = 2 * 3  # frames per clip × views, view-major: the head view's rows first
    assert markers.shape[0] == actions.shape[0] == np.load(cache / "inputs.npy").shape[0]
    assert markers[:2].any() and not markers[2:per].any()  # Γ is drawn in the head view only
    model = load_world_model(out)
    assert isinstance(model, CompositeWorldModel) and model.switches == sw
    # the settings of a run are its identity: resuming it as another variant is refused
    with pytest.raises(ValueError, match="switches"):
        train_composite(TrainSettings(**base), tmp_path / "b", progress=False, rig=rig32, cache_dir=cache)  # type: ignore[arg-type]
    spec = CacheSpec(str(dataset), "configs/rig/sim_dual_ur5e.yaml", size=16, frames_per_clip=2, max_clips=12)
    with pytest.raises(ValueError, match="no complete cache"):
        build_extras(spec, cache, rig=rig32)


def test_success_only_trains_on_successful_episodes_only(dataset: Path) -> None:
    episodes = np.arange(6)
    ok = _successful(str(dataset), episodes)
    from pilworld.data.clip_dataset import episode_success

    truth = episode_success(dataset, 6, None)
    np.testing.assert_array_equal(ok, truth == 1)
    assert ok.any() and not ok.all()  # the synthetic set has both, so the filter is exercised


def test_an_old_run_without_the_variant_settings_resumes_as_the_shipped_recipe(
    dataset: Path, tmp_path: Path, rig32: RigConfig
) -> None:
    base = dict(
        data=str(dataset), steps=4, batch=6, width=8, work_size=8, cache_size=32, max_clips=12, frames_per_clip=2
    )
    run = tmp_path / "old"
    assert train_composite(TrainSettings(**base), run, progress=False, rig=rig32, stop_after=2) is None  # type: ignore[arg-type]
    settings = json.loads((run / "settings.json").read_text())
    del settings["switches"], settings["success_only"]  # as written before the variant switches existed
    (run / "settings.json").write_text(json.dumps(settings))
    assert train_composite(TrainSettings(**base), run, progress=False, rig=rig32) is not None  # type: ignore[arg-type]
