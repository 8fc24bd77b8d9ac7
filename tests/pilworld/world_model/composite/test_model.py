"""World model v2 behind the WorldModel interface: shapes, state, exact robot pixels, checkpoints, the env."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np
import pytest
import torch

from pilworld.config.rig import RigConfig
from pilworld.control_video.gamma import ControlVideo
from pilworld.envs import ImaginedEnv
from pilworld.reference.paper_tasks import task_spec
from pilworld.types import ARM_LAYOUT, ChunkSpec, Observation, Start, Subtask
from pilworld.world_model.base import PredictRequest
from pilworld.world_model.composite.checkpoint import is_composite, load_composite, save_composite
from pilworld.world_model.composite.model import CompositeConfig, CompositeWorldModel
from pilworld.world_model.composite.net import CANDIDATES
from pilworld.world_model.loader import load_world_model
from simrig.poses import HOME_Q14

SPEC = ChunkSpec()
LEFT_ARM, LEFT_GRIP = ARM_LAYOUT["left"]


@pytest.fixture
def model(rig32: RigConfig) -> CompositeWorldModel:
    torch.manual_seed(0)
    m = CompositeWorldModel(CompositeConfig(image_size=32, work_size=8), rig32)
    return m.eval()


def _request(model: CompositeWorldModel, state: np.ndarray | None = None) -> PredictRequest:
    rng = np.random.default_rng(0)
    q = HOME_Q14.astype(np.float64).copy() if state is None else state
    stride = np.repeat(q[None], SPEC.frames, 0)
    stride[:, LEFT_ARM.start] += np.linspace(0.0, -0.4, SPEC.frames)
    return PredictRequest.build(
        model.info,
        current={v: rng.integers(0, 255, (32, 32, 3), dtype=np.uint8) for v in model.info.views},
        history=None,
        control=np.zeros((SPEC.frames, 32, 32, 3), np.uint8),
        actions=stride,
        instruction="sort the cubes.",
        state=q,
    )


def _force_gate(model: CompositeWorldModel, candidate: int) -> None:
    """Make every gate pick one candidate, whatever the input."""
    with torch.no_grad():
        model.net.head.weight.zero_()
        model.net.head.bias.zero_()  # type: ignore[union-attr]
        model.net.head.bias[candidate] = 50.0  # type: ignore[index]


def test_predict_with_state_shapes_and_arm_state(model: CompositeWorldModel) -> None:
    req = _request(model)
    frames, states = model.predict_with_state(req)
    assert set(frames) == set(model.info.views)
    for f in frames.values():
        assert f.shape == (SPEC.frames, 32, 32, 3) and f.dtype == np.uint8
    assert states.shape == (SPEC.frames, 14) and np.all(np.isfinite(states))
    layers = model.builder(dict(req.current), req.state, req.actions)  # type: ignore[arg-type]
    arms = [i for i in range(14) if i not in (ARM_LAYOUT["left"][1], ARM_LAYOUT["right"][1])]
    np.testing.assert_allclose(states[:, arms], layers.poses[:, arms], atol=1e-6)  # the lagged commands
    assert np.all((states[:, [6, 13]] >= 0) & (states[:, [6, 13]] <= 1))
    np.testing.assert_array_equal(model.predict(req)["cam_high"], frames["cam_high"])  # deterministic


def test_robot_pixels_come_from_the_painter(model: CompositeWorldModel) -> None:
    req = _request(model)
    layers = model.builder(dict(req.current), req.state, req.actions)  # type: ignore[arg-type]
    with torch.no_grad():
        for p in model.painter.net[-1].parameters():
            p.zero_()
        model.painter.net[-1].bias.fill_(10.0)  # type: ignore[union-attr]  # paints white
    frames = model.predict(req)
    on = layers.parts["cam_high"] > 0
    assert on.any()
    assert (frames["cam_high"][on] == 255).all()


def test_a_confident_prior_gate_copies_the_static_scene(model: CompositeWorldModel) -> None:
    req = _request(model)
    layers = model.builder(dict(req.current), req.state, req.actions)  # type: ignore[arg-type]
    _force_gate(model, CANDIDATES.index("prior"))
    frames = model.predict(req)
    v = "cam_high"
    keep = layers.prior_valid[v] & (layers.parts[v] == 0)
    assert keep.any()
    diff = np.abs(frames[v].astype(int) - layers.prior[v].astype(int))[keep]
    assert diff.max() <= 1


def test_the_state_is_required(model: CompositeWorldModel) -> None:
    req = _request(model)
    bare = PredictRequest(req.current, req.history, req.history_valid, req.control, req.actions, req.instruction)
    with pytest.raises(ValueError, match="state"):
        model.predict_with_state(bare)
    with pytest.raises(ValueError, match="state"):
        PredictRequest.build(
            model.info,
            current=dict(req.current),
            history=None,
            control=req.control,
            actions=req.actions,
            instruction="x",
            state=np.full(14, np.nan),
        )


def test_checkpoint_round_trip(model: CompositeWorldModel, tmp_path: Path, rig32: RigConfig) -> None:
    folder = save_composite(model, tmp_path / "v2")
    assert is_composite(folder)
    again = load_world_model(folder)
    assert isinstance(again, CompositeWorldModel)
    again.bind_rig(rig32)
    req = _request(model)
    np.testing.assert_array_equal(again.predict(req)["cam_left_wrist"], model.predict(req)["cam_left_wrist"])
    with pytest.raises(ValueError, match="adapter"):
        load_world_model(folder, adapter="sort_cubes")
    with pytest.raises(ValueError, match="image size"):
        again.bind_rig(RigConfig.model_validate({**rig32.model_dump(), "image_size": {"width": 64, "height": 64}}))
    assert isinstance(load_composite(folder), CompositeWorldModel)


class _StateModel:
    """A model that predicts a state of its own: the env must hand it to the policy."""

    def __init__(self, inner: CompositeWorldModel) -> None:
        self.inner = inner
        self.seen_state: np.ndarray | None = None

    @property
    def info(self):  # type: ignore[no-untyped-def]
        return self.inner.info

    def predict_with_state(self, request: PredictRequest, *, steps: int | None = None, seed: int = 0):  # type: ignore[no-untyped-def]
        self.seen_state = request.state
        frames, states = self.inner.predict_with_state(request)
        states[:, LEFT_GRIP] = 0.42
        return frames, states

    def predict(self, request, *, steps=None, seed=0):  # type: ignore[no-untyped-def]
        raise AssertionError("the env must prefer predict_with_state")

    def predict_batch(self, batch, *, steps=None, seed=0):  # type: ignore[no-untyped-def]
        raise AssertionError("unused")


def test_the_imagined_branch_reports_the_predicted_state(model: CompositeWorldModel, rig32: RigConfig) -> None:
    wrapped = _StateModel(model)
    env = ImaginedEnv(wrapped, ControlVideo.from_rig(rig32, SPEC), SPEC)  # type: ignore[arg-type]
    q = HOME_Q14.astype(np.float32)
    rng = np.random.default_rng(3)
    obs = Observation(
        images={v: rng.integers(0, 255, (32, 32, 3), dtype=np.uint8) for v in model.info.views}, state=q, timestamp=0.0
    )
    env.reset(Start(Subtask("sort_cubes", 0, "sort the cubes."), obs))
    chunk = np.repeat(q[None], 50, 0)
    seg = env.step(chunk)
    assert wrapped.seen_state is not None
    np.testing.assert_array_equal(wrapped.seen_state, q)
    assert all(o.state[LEFT_GRIP] == pytest.approx(0.42) for o in seg.observations)
    env.step(chunk)
    assert wrapped.seen_state[LEFT_GRIP] == pytest.approx(0.42)  # the next round starts from it


def test_weights_of_other_layer_code_are_refused(model: CompositeWorldModel, tmp_path: Path) -> None:
    import json

    folder = save_composite(model, tmp_path / "old")
    cfg = json.loads((folder / "config.json").read_text())
    del cfg["config"]["layout"]
    (folder / "config.json").write_text(json.dumps(cfg))
    with pytest.raises(ValueError, match="layer version"):
        load_composite(folder)


def test_away_from_the_hands_the_scene_is_kept_whatever_the_gates_say(model: CompositeWorldModel) -> None:
    req = _request(model)
    layers = model.builder(dict(req.current), req.state, req.actions)  # type: ignore[arg-type]
    _force_gate(model, CANDIDATES.index("generated"))  # every gate on the generated fill
    frames = model.predict(req)
    v = "cam_high"
    kept = layers.prior_valid[v] & (layers.parts[v] == 0) & ~layers.hands[v]
    assert kept.any()
    diff = np.abs(frames[v].astype(int) - layers.prior[v].astype(int))[kept]
    assert diff.max() <= 1
    free = layers.prior_valid[v] & (layers.parts[v] == 0) & layers.hands[v]
    if free.any():  # inside the hand region the gates rule: the (untrained) fill differs from the prior
        assert np.abs(frames[v].astype(int) - layers.prior[v].astype(int))[free].mean() > 1


def test_objects_can_be_turned_off(rig32: RigConfig) -> None:
    off = CompositeWorldModel(CompositeConfig(image_size=32, work_size=8, objects=False), rig32).eval()
    req = _request(off)
    assert req.state is not None
    off.begin_rollout(dict(req.current), req.state, req.instruction)
    assert off._scene is None and off._scene_for(req) is None
    on = CompositeWorldModel(CompositeConfig(image_size=32, work_size=8), rig32).eval()
    sort = task_spec("sort_cubes").instruction
    req = dataclasses.replace(req, instruction=sort)
    on.begin_rollout(dict(req.current), req.state, sort)
    assert on._scene is not None and on._scene_for(req) is on._scene  # the same state continues the rollout
    other = dataclasses.replace(_request(on, HOME_Q14.astype(np.float64) + 0.01), instruction=sort)
    assert on._scene_for(other) is not on._scene
    on.begin_rollout(dict(req.current), req.state, "fold the towel.")  # a task the knowledge does not list
    assert on._scene is None


def test_the_byte_composite_equals_the_float_one() -> None:
    """Inference's uint8 composite is the training composite rounded to bytes, pixel for pixel (up to the
    painter's table, equal to its MLP within float error)."""
    from pilworld.world_model.composite.cache import BASE_CHANNELS
    from pilworld.world_model.composite.model import blend, blend_bytes
    from pilworld.world_model.composite.net import RobotPainter

    torch.manual_seed(0)
    g = torch.Generator().manual_seed(1)
    n, s = 9, 32
    x = torch.randint(0, 256, (n, BASE_CHANNELS, s, s), dtype=torch.uint8, generator=g)
    for c in (3, 10, 14, 24, 25):  # flags are 0 or 255
        x[:, c] = torch.where(torch.rand(n, s, s, generator=g) < 0.6, 255, 0).to(torch.uint8)
    ids = torch.randint(0, 5, (n, s, s), generator=g) * (torch.rand(n, s, s, generator=g) < 0.3)
    x[:, 15:19] = torch.stack([(ids == p) for p in range(1, 5)], 1).to(torch.uint8) * 255  # one part per pixel
    scal = torch.zeros(n, 8)
    scal[:, 5] = torch.arange(n) % 3  # head and both wrist views
    gates = torch.randn(n, len(CANDIDATES), 8, 8, generator=g) * 3
    generated = torch.rand(n, 3, 8, 8, generator=g)
    painter = RobotPainter()
    plate = torch.rand(3, s, s, generator=g)
    want = (blend(x.float() / 255.0, scal, gates, generated, painter, plate).clamp(0, 1) * 255.0).round()
    want = want.to(torch.uint8)
    got = blend_bytes(x, scal, gates, generated, painter, plate)
    assert got.dtype == torch.uint8 and got.shape == want.shape
    assert (got.int() - want.int()).abs().max() <= 1  # float rounding at .5 only
    assert (got != want).float().mean() < 1e-3
    free = ((x[:, 25] > 127) | ~((x[:, 3] > 127) | (x[:, 24] > 127))) & (ids == 0)
    assert free.any() and (ids > 0).any() and (~free & (ids == 0)).any()  # every path was exercised
    # Candidates valid nowhere (no carry layers, as with tracked objects; wrist views only: no plate) are
    # skipped, and that changes nothing.
    x[:, 10] = 0
    x[:, 14] = 0
    scal[:, 5] = 1 + torch.arange(n) % 2
    want = (blend(x.float() / 255.0, scal, gates, generated, painter, plate).clamp(0, 1) * 255.0).round()
    want = want.to(torch.uint8)
    got = blend_bytes(x, scal, gates, generated, painter, plate)
    assert (got.int() - want.int()).abs().max() <= 1 and (got != want).float().mean() < 1e-3
