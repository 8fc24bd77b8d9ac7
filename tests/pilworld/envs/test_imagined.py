"""ImaginedEnv: control video → world model → K observations; the history memory takes generated frames."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from pilworld.config.rig import RigConfig
from pilworld.control_video.gamma import ControlVideo
from pilworld.envs import EnvError, HistoryMemory, ImaginedEnv
from pilworld.types import ChunkSpec, Observation, Start, Subtask
from pilworld.world_model.base import FrozenWorldModel, PredictRequest, WorldModelBatch, WorldModelInfo

SIM = "configs/rig/sim_dual_ur5e.yaml"
VIEWS = ("cam_high", "cam_left_wrist", "cam_right_wrist")
SPEC = ChunkSpec()


class SpyModel:
    """Returns frames filled with a running counter and records every request it sees."""

    def __init__(self, history: int = 5, size: int = 128) -> None:
        self._info = WorldModelInfo(views=VIEWS, height=size, width=size, future=SPEC.frames, history=history)
        self.requests: list[PredictRequest] = []
        self.seeds: list[int] = []
        self.counter = 0

    @property
    def info(self) -> WorldModelInfo:
        return self._info

    def predict_batch(self, batch: WorldModelBatch, *, steps: int | None = None, seed: int = 0) -> torch.Tensor:
        raise NotImplementedError

    def predict(self, request: PredictRequest, *, steps: int | None = None, seed: int = 0) -> dict[str, np.ndarray]:
        self.requests.append(request)
        self.seeds.append(seed)
        K, H, W = self._info.future, self._info.height, self._info.width
        out = {}
        for i, v in enumerate(VIEWS):
            values = (self.counter + np.arange(K)) % 200 + i
            out[v] = np.broadcast_to(values[:, None, None, None], (K, H, W, 3)).astype(np.uint8).copy()
        self.counter += K
        return out


def _obs(value: int, t: float, size: int = 128) -> Observation:
    images = {v: np.full((size, size, 3), value, dtype=np.uint8) for v in VIEWS}
    state = np.zeros(14, dtype=np.float32)
    state[[6, 13]] = 1.0
    return Observation(images=images, state=state, timestamp=t)


def _start(history: int = 5) -> Start:
    hist = tuple(_obs(250 - k, 0.1 * k) for k in range(history))
    return Start(Subtask("sort_cubes", 0, "sort the cubes"), _obs(240, 0.5), hist)


def _chunk(seed: int = 0) -> np.ndarray:
    rng = np.random.default_rng(seed)
    base = np.array([0, -1.2, 1.5, -1.9, -1.57, 0, 1, 0, -1.9, -1.5, -1.2, 1.57, 0, 1], dtype=np.float32)
    return (base + rng.normal(0, 0.02, (SPEC.horizon, 14))).astype(np.float32)


@pytest.fixture(scope="module")
def gamma() -> ControlVideo:
    return ControlVideo.from_rig(RigConfig.load(SIM), SPEC)


def test_step_returns_k_frames_with_policy_side_state_and_times(gamma: ControlVideo) -> None:
    model = SpyModel()
    env = ImaginedEnv(model, gamma, SPEC, control_rate_hz=30.0, seed=3)
    start = _start()
    assert env.reset(start) is start.observation
    chunk = _chunk()
    seg = env.step(chunk)
    assert len(seg.observations) == SPEC.frames and seg.stride == SPEC.stride
    np.testing.assert_array_equal(seg.actions, chunk[: SPEC.executed_steps])
    for k, o in enumerate(seg.observations):
        np.testing.assert_array_equal(o.state, chunk[(k + 1) * SPEC.stride - 1])  # the stride-aligned action
        assert o.timestamp == pytest.approx(0.5 + (k + 1) * SPEC.stride / 30.0)
        assert set(o.views) == set(VIEWS) and o.images["cam_high"].dtype == np.uint8
    req = model.requests[0]
    assert req.instruction == "sort the cubes"
    np.testing.assert_array_equal(req.control, gamma.render_batch(chunk[None], start.observation.state[None])[0])


def test_history_memory_starts_real_then_takes_generated_frames(gamma: ControlVideo) -> None:
    model = SpyModel()
    env = ImaginedEnv(model, gamma, SPEC, seed=1)
    env.reset(_start())
    env.step(_chunk(0))
    first = model.requests[0]
    assert first.history_valid.all()
    assert [int(f[0, 0, 0]) for f in first.history["cam_high"]] == [250, 249, 248, 247, 246]
    assert int(first.current["cam_high"][0, 0, 0]) == 240
    env.step(_chunk(1))
    second = model.requests[1]
    # Round 1 generated counter values 0..14 for cam_high: the new current is frame 14 and the memory
    # holds the five generated frames before it (stride Δ apart, as in training clips).
    assert int(second.current["cam_high"][0, 0, 0]) == 14
    assert [int(f[0, 0, 0]) for f in second.history["cam_high"]] == [9, 10, 11, 12, 13]
    assert [int(f[0, 0, 0]) for f in second.history["cam_left_wrist"]] == [10, 11, 12, 13, 14]
    assert model.seeds == [1000, 1001]  # fixed per (env seed, round): reruns reproduce the rollout


def test_short_start_history_is_padded_and_flagged_invalid(gamma: ControlVideo) -> None:
    model = SpyModel()
    env = ImaginedEnv(model, gamma, SPEC)
    env.reset(_start(history=2))
    env.step(_chunk())
    req = model.requests[0]
    assert req.history_valid.tolist() == [False, False, False, True, True]
    assert [int(f[0, 0, 0]) for f in req.history["cam_high"]] == [250, 250, 250, 250, 249]


def test_memory_unit() -> None:
    mem = HistoryMemory(["a"], 3)
    mem.reset([], _obs_one(7))
    frames, valid = mem.arrays()
    assert valid.tolist() == [False, False, False] and frames["a"].shape == (3, 2, 2, 3)
    for v in (1, 2, 3, 4):
        mem.push({"a": np.full((2, 2, 3), v, np.uint8)})
    frames, valid = mem.arrays()
    assert valid.tolist() == [True, True, True] and [int(f[0, 0, 0]) for f in frames["a"]] == [2, 3, 4]


def _obs_one(v: int) -> Observation:
    return Observation(images={"a": np.full((2, 2, 3), v, np.uint8)}, state=np.zeros(14, np.float32), timestamp=0.0)


def test_errors_name_the_problem(gamma: ControlVideo) -> None:
    env = ImaginedEnv(SpyModel(), gamma, SPEC)
    with pytest.raises(EnvError, match="before reset"):
        env.step(_chunk())
    env.reset(_start())
    with pytest.raises(ValueError, match="finite"):
        bad = _chunk()
        bad[3, 2] = np.nan
        env.step(bad)
    with pytest.raises(ValueError, match="K·Δ"):
        env.step(_chunk()[:20])
    with pytest.raises(ValueError, match="14 action dimensions"):
        env.step(_chunk()[:, :7])
    with pytest.raises(EnvError, match="world model expects"):
        ImaginedEnv(SpyModel(size=64), gamma, SPEC)
    with pytest.raises(EnvError, match="frames per call"):
        ImaginedEnv(SpyModel(), gamma, ChunkSpec(frames=10))


def test_start_views_must_match_the_model(gamma: ControlVideo) -> None:
    env = ImaginedEnv(SpyModel(), gamma, SPEC)
    obs = Observation(
        images={"cam_high": np.zeros((128, 128, 3), np.uint8)}, state=np.zeros(14, np.float32), timestamp=0
    )
    with pytest.raises(EnvError, match="views"):
        env.reset(Start(Subtask("sort_cubes", 0, "x"), obs))


def test_frozen_model_reproduces_the_start(gamma: ControlVideo) -> None:
    info = WorldModelInfo(views=VIEWS, height=128, width=128, future=SPEC.frames, history=5)
    env = ImaginedEnv(FrozenWorldModel(info), gamma, SPEC)
    start = _start()
    env.reset(start)
    seg = env.step(_chunk())
    for o in seg.observations:
        np.testing.assert_array_equal(o.images["cam_high"], start.observation.images["cam_high"])


def test_safety_filter_shapes_the_commands_like_on_the_robot(gamma: ControlVideo) -> None:
    """A chunk that jumps is slowed down by the robot's filter; the imagined branch executes the same commands."""
    from pilworld.envs import SafetyFilter
    from simrig.robot import SimRobot

    with SimRobot(SIM, "sort_cubes") as robot:
        spec = robot.spec
    model = SpyModel()
    env = ImaginedEnv(model, gamma, SPEC, safety=SafetyFilter(spec))
    start = _start()
    env.reset(start)
    jump = np.tile(start.observation.state + np.float32(0.2), (SPEC.horizon, 1))
    jump[:, [6, 13]] = 1.0
    seg = env.step(jump)
    reference = SafetyFilter(spec)
    reference.reset(start.observation.state)
    expected = np.stack([reference(a) for a in jump[: SPEC.executed_steps]])
    np.testing.assert_array_equal(seg.actions, expected)
    assert not np.allclose(seg.actions[0], jump[0])  # the first step was slowed down
    np.testing.assert_array_equal(model.requests[0].actions, expected[SPEC.stride_indices()])
    np.testing.assert_array_equal(seg.observations[-1].state, expected[-1])
