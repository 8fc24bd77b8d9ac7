"""RobotEnv on the simulated rig, the safety filter, and one closed loop driving both branches alike."""

from __future__ import annotations

from collections.abc import Iterator
from typing import Any

import numpy as np
import pytest

from hw_drivers.errors import SafetyViolationError, StaleObservationError
from pilworld.config.rig import RigConfig
from pilworld.control_video.gamma import ControlVideo
from pilworld.envs import EnvError, ImaginedEnv, RobotEnv
from pilworld.policies.base import CallablePolicy, PolicyError
from pilworld.policies.scripted import ScriptedPolicy
from pilworld.rollout import closed_loop
from pilworld.types import ChunkSpec, Observation, Segment
from pilworld.world_model import DEFAULT_CHECKPOINT
from pilworld.world_model.loader import load_world_model
from simrig.robot import SimRobot

SIM = "configs/rig/sim_dual_ur5e.yaml"
SPEC = ChunkSpec(rounds=2)


@pytest.fixture(scope="module")
def robot() -> Iterator[SimRobot]:
    with SimRobot(SIM, "sort_cubes") as r:
        yield r


def test_robot_env_filters_every_command(robot: SimRobot) -> None:
    """The sim robot's filter: its clock for staleness, clipping to the speed cap, refusing NaN and jumps."""
    start = robot.reset(seed=0, subtask=0)
    env = RobotEnv(robot, SPEC, pace=False)
    assert env.safety.clock is not None and env.safety.clock() == robot.time
    env.reset(start)
    q = start.observation.state.astype(np.float64)
    chunk = np.tile(q, (SPEC.horizon, 1))
    chunk[1:, 0] += 0.2  # after the first command: under the step cap, faster than the arm's speed
    seg = env.step(chunk)
    assert np.all(np.abs(np.diff(seg.actions[:, 0])) <= np.pi / 30 + 1e-5)
    jump = np.tile(seg.last.state.astype(np.float64), (SPEC.horizon, 1))
    jump[3:, 2] += 0.5  # a jump no controller should be asked for in one control period
    with pytest.raises(SafetyViolationError, match="max_step"):
        env.step(jump)


def test_robot_env_refuses_a_stale_start(robot: SimRobot) -> None:
    start = robot.reset(seed=0, subtask=0)
    env = RobotEnv(robot, SPEC, pace=False)
    env.reset(start)
    for _ in range(45):  # 1.5 s of simulated time pass before the first chunk arrives
        robot.send_action(start.observation.state)
    with pytest.raises(StaleObservationError, match="s old"):
        env.step(np.tile(start.observation.state, (SPEC.horizon, 1)))


def test_robot_env_records_k_frames_at_stride(robot: SimRobot) -> None:
    start = robot.reset(seed=0, subtask=0)
    env = RobotEnv(robot, SPEC, pace=False)
    assert env.reset(start) is start.observation
    chunk = np.tile(start.observation.state, (SPEC.horizon, 1))
    seg = env.step(chunk)
    assert len(seg.observations) == SPEC.frames and seg.actions.shape == (SPEC.executed_steps, 14)
    dt = [b.timestamp - a.timestamp for a, b in zip(seg.observations, seg.observations[1:], strict=False)]
    assert np.allclose(dt, SPEC.stride / 30.0)
    assert robot.steps == SPEC.executed_steps


def test_robot_env_refuses_a_robot_away_from_the_start(robot: SimRobot) -> None:
    start = robot.reset(seed=0, subtask=0)
    moved = start.observation.state.copy()
    moved[0] += 0.3
    for _ in range(20):
        robot.send_action(moved)
    with pytest.raises(SafetyViolationError, match="not at the start"):
        RobotEnv(robot, SPEC, pace=False).reset(start)
    with pytest.raises(EnvError, match="before reset"):
        RobotEnv(robot, SPEC, pace=False).step(np.zeros((50, 14), np.float32))


def test_policy_sees_the_same_kind_of_observation_from_both_branches(robot: SimRobot) -> None:
    """Type, views, shape and dtype of every observation the policy receives match across branches."""
    rig = RigConfig.load(SIM)
    seen: dict[str, list[Observation]] = {"real": [], "imagined": []}
    scripted = ScriptedPolicy(rig, horizon=SPEC.horizon)
    branch = "real"

    def spy(obs: Observation, instruction: str) -> np.ndarray:
        seen[branch].append(obs)
        return scripted.infer(obs, instruction)

    policy = CallablePolicy(spy, "spy")
    start = robot.reset(seed=1, subtask=0)
    imagined = ImaginedEnv(load_world_model(DEFAULT_CHECKPOINT), ControlVideo.from_rig(rig, SPEC), SPEC)
    branch = "imagined"
    scripted.reset(seed=1)
    closed_loop(policy, imagined, start.subtask.instruction, SPEC.rounds, start=start)
    branch = "real"
    scripted.reset(seed=1)
    out = closed_loop(policy, RobotEnv(robot, SPEC, pace=False), start.subtask.instruction, SPEC.rounds, start=start)
    assert len(out.segments) == SPEC.rounds and len(out.observations) == 1 + SPEC.rounds * SPEC.frames
    assert len(seen["real"]) == len(seen["imagined"]) == SPEC.rounds
    assert seen["real"][0] is seen["imagined"][0] is start.observation  # the same start, byte for byte
    for a, b in zip(seen["real"], seen["imagined"], strict=True):
        assert type(a) is type(b) is Observation
        assert a.views == b.views
        for v in a.views:
            assert a.images[v].shape == b.images[v].shape and a.images[v].dtype == b.images[v].dtype == np.uint8
        assert a.state.shape == b.state.shape and a.state.dtype == b.state.dtype == np.float32
        assert isinstance(a.timestamp, float) and isinstance(b.timestamp, float)


def test_closed_loop_validates_its_arguments(robot: SimRobot) -> None:
    start = robot.reset(seed=0, subtask=0)
    env = RobotEnv(robot, SPEC, pace=False)
    ok = CallablePolicy(lambda o, i: np.tile(o.state, (50, 1)))
    with pytest.raises(ValueError, match="rounds"):
        closed_loop(ok, env, "x", 0, start=start)
    with pytest.raises(ValueError, match="instruction"):
        closed_loop(ok, env, " ", 1, start=start)
    bad = CallablePolicy(lambda o, i: np.full((50, 14), np.nan), "nanny")
    with pytest.raises(PolicyError, match=r"nanny.*finite"):
        closed_loop(bad, env, "x", 1, start=start)


def test_closed_loop_stop_on_ends_the_rollout_after_the_first_round(robot: SimRobot) -> None:
    """A stop_on error in round 2 keeps round 1 and says why; the same error in round 1 propagates."""

    class Refusing(RobotEnv):
        def __init__(self, refuse_at: int) -> None:
            super().__init__(robot, ChunkSpec(rounds=3), pace=False)
            self.calls, self.refuse_at = 0, refuse_at

        def step(self, chunk: Any) -> Segment:
            self.calls += 1
            if self.calls == self.refuse_at:
                raise SafetyViolationError("SimRobot", "max_step", "left_joint_1 would move 0.41 (test)")
            return super().step(chunk)

    hold = CallablePolicy(lambda o, i: np.tile(o.state, (50, 1)))
    start = robot.reset(seed=0, subtask=0)
    out = closed_loop(hold, Refusing(2), "sort", 3, start=start, stop_on=(SafetyViolationError,))
    assert len(out.segments) == 1 and "SafetyViolationError" in out.stopped and "left_joint_1" in out.stopped
    start = robot.reset(seed=0, subtask=0)
    with pytest.raises(SafetyViolationError):
        closed_loop(hold, Refusing(1), "sort", 3, start=start, stop_on=(SafetyViolationError,))
    start = robot.reset(seed=0, subtask=0)
    with pytest.raises(SafetyViolationError):  # without stop_on it propagates in any round
        closed_loop(hold, Refusing(2), "sort", 3, start=start)
