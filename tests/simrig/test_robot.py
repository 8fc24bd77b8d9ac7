"""``SimRobot``: the ``Robot`` contract, every task's reset/step/observe, servo tracking, the action
filter, the privileged subtask checker, determinism and argument errors."""

from __future__ import annotations

import itertools
from collections.abc import Callable
from pathlib import Path

import numpy as np
import pytest

from hw_drivers.robot import DeviceNotConnectedError, Robot
from pilworld.types import LEFT_ARM, LEFT_GRIP, RIGHT_ARM, RIGHT_GRIP, Observation
from simrig.robot import HOME_Q14, SimRobot
from simrig.tasks import TASK_NAMES, ObjectPose, load_task

ROOT = Path(__file__).resolve().parents[2]
SIM = ROOT / "configs" / "rig" / "sim_dual_ur5e.yaml"
ARM = np.r_[LEFT_ARM, RIGHT_ARM]  # the 12 arm joints of the 14-d vector
GRIPS = np.array([LEFT_GRIP, RIGHT_GRIP])
SIZE = (128, 128, 3)


def _check_observation(robot: SimRobot, obs: Observation) -> None:
    assert obs.views == robot.spec.cameras == ("cam_high", "cam_left_wrist", "cam_right_wrist")
    for view, image in obs.images.items():
        assert image.dtype == np.uint8 and image.shape == SIZE, view
        assert image.std() > 1.0, f"{view} is blank"
    assert obs.state.dtype == np.float32 and obs.state.shape == (14,)
    assert np.all(np.isfinite(obs.state))
    _check_within_limits(robot, obs.state)


def _check_within_limits(robot: SimRobot, state: np.ndarray) -> None:
    lo, hi = robot.spec.lower_array, robot.spec.upper_array
    over = np.maximum(lo - state, state - hi)
    assert over[ARM].max() <= 1e-4, f"arm joints beyond their limits by {over[ARM]}"
    # A closed finger is pressed into its joint stop (the grip squeezes): a soft limit, a few tenths of a mm.
    assert over[GRIPS].max() <= 0.02, f"grips beyond [0, 1] by {over[GRIPS]}"


# ---------------------------------------------------------------------- the Robot contract


def test_sim_robot_implements_the_robot_protocol() -> None:
    robot = SimRobot(SIM, "sort_cubes")
    assert isinstance(robot, Robot)
    assert not robot.is_connected
    with pytest.raises(DeviceNotConnectedError, match="not connected; call connect") as info:
        robot.observe()
    assert info.value.device == "sim:sim_dual_ur5e"
    for call in (robot.state, lambda: robot.send_action(HOME_Q14), robot.reset, robot.check_subtask):
        with pytest.raises(DeviceNotConnectedError):
            call()
    spec = robot.spec
    assert spec.dof == 14 and spec.control_rate_hz == 30.0 and spec.image_size == (128, 128)
    assert spec.max_joint_speed is not None and spec.max_joint_speed[0] == pytest.approx(np.pi)


def test_context_manager_connects_and_disconnects() -> None:
    with SimRobot(SIM, "stack_blocks") as robot:
        assert robot.is_connected
        robot.connect()  # a second connect is harmless
        _check_observation(robot, robot.observe())
    assert not robot.is_connected
    with pytest.raises(DeviceNotConnectedError):
        robot.observe()


# ---------------------------------------------------------------------- every task: reset, step, observe


@pytest.mark.parametrize("task", TASK_NAMES)
def test_task_reset_step_observe(robots: Callable[[str], SimRobot], task: str) -> None:
    robot = robots(task)
    rng = np.random.default_rng(42)
    for subtask in range(robot.task.num_subtasks):
        start = robot.reset(seed=subtask + 1, subtask=subtask, history=5, stride=3)
        assert start.subtask.task == task and start.subtask.index == subtask
        assert start.subtask.instruction == load_task(task).instruction and start.subtask.seed == subtask + 1
        assert len(start.history) == 5
        stamps = [o.timestamp for o in (*start.history, start.observation)]
        assert all(b > a for a, b in itertools.pairwise(stamps)), stamps
        np.testing.assert_allclose(np.diff(stamps[:-1]), 3 / 30, atol=1e-9)  # stride Δ at 30 Hz
        for obs in (*start.history, start.observation):
            assert set(obs.views) == set(start.observation.views)
            _check_observation(robot, obs)
        np.testing.assert_allclose(robot.command(), HOME_Q14, atol=1e-6)  # the lead-in ends at home
        assert robot.steps == 0
        clamped = 0
        for _ in range(60):
            # Jumpy wishes around home (the gripper stays clear of the table): the robot rate-limits them.
            wish = HOME_Q14 + rng.uniform(-0.2, 0.2, 14)
            wish[GRIPS] = rng.uniform(-0.2, 1.2, 2)
            last = robot.command()
            sent = robot.send_action(wish)
            assert sent.dtype == np.float32 and sent.shape == (14,) and np.all(np.isfinite(sent))
            assert np.all(np.abs(sent - last) <= np.asarray(robot.spec.max_joint_speed) / 30 + 1e-6)
            clamped += int(np.abs(sent - wish).max() > 1e-6)
            _check_within_limits(robot, robot.state())
        assert robot.steps == 60 and clamped > 30
        assert np.all(np.isfinite(robot._data.qpos)) and np.all(np.isfinite(robot._data.qvel))
        obs = robot.observe()
        _check_observation(robot, obs)
        assert obs.timestamp == pytest.approx(start.observation.timestamp + 60 / 30)
        poses = robot.object_poses()
        assert set(poses) == {o.name for o in robot.task.objects()}
        assert all(np.all(np.isfinite(p.position)) and p.position[2] > -0.05 for p in poses.values())


# ---------------------------------------------------------------------- servo tracking (acceptance)


@pytest.mark.parametrize("sign", [1.0, -1.0])
def test_arm_joints_track_a_step_within_one_second(robots: Callable[[str], SimRobot], sign: float) -> None:
    robot = robots("sort_cubes")
    robot.reset(seed=0, subtask=0, history=5)
    for _ in range(20):  # come to rest at home
        robot.send_action(HOME_Q14)
    assert np.abs(robot.state()[ARM] - HOME_Q14[ARM]).max() < 1e-3
    target = HOME_Q14.copy()
    target[ARM] += sign * 0.3 * np.tile([1.0, -1.0, 1.0, -1.0, 1.0, -1.0], 2)
    errors = []
    for _ in range(30):  # 1 s at 30 Hz
        robot.send_action(target)
        errors.append(float(np.abs(robot.state()[ARM] - target[ARM]).max()))
    np.testing.assert_allclose(robot.command()[ARM], target[ARM], atol=1e-6)
    misses = np.nonzero(np.array(errors) >= 0.01)[0]
    assert misses.size < len(errors), f"max |state - target| after 1 s: {errors[-1]:.4f} rad"
    settled = int(misses[-1]) + 1 if misses.size else 0  # the first step after which it stays below
    settle_s = (settled + 1) / 30
    print(f"step of {sign * 0.3:+.1f} rad on every arm joint: below 0.01 rad from {settle_s:.3f} s on")
    assert settle_s <= 1.0


# ---------------------------------------------------------------------- the action filter


def test_send_action_rejects_malformed_commands(robots: Callable[[str], SimRobot]) -> None:
    robot = robots("sort_cubes")
    robot.reset(seed=0, subtask=0, history=0)
    before = robot.command().copy()
    with pytest.raises(ValueError, match=r"action: expected shape \(14,\), got \(13,\)"):
        robot.send_action(np.zeros(13))
    with pytest.raises(ValueError, match=r"action: expected shape \(14,\), got \(2, 14\)"):
        robot.send_action(np.zeros((2, 14)))
    bad = HOME_Q14.copy()
    bad[3] = np.nan
    with pytest.raises(ValueError, match="action: must be finite"):
        robot.send_action(bad)
    bad[3] = np.inf
    with pytest.raises(ValueError, match="action: must be finite"):
        robot.send_action(bad)
    np.testing.assert_array_equal(robot.command(), before)  # nothing was applied
    assert robot.steps == 0


def test_send_action_clamps_limits_and_speed(robots: Callable[[str], SimRobot]) -> None:
    robot = robots("sort_cubes")
    robot.reset(seed=0, subtask=0, history=5)
    spec = robot.spec
    step = np.asarray(spec.max_joint_speed) / spec.control_rate_hz
    np.testing.assert_allclose(step[ARM], np.pi / 30)
    np.testing.assert_allclose(step[GRIPS], 2.0 / 30)
    last = robot.command().astype(np.float64)
    assert np.all(last[GRIPS] == 1.0)  # open at home

    # Within the speed limit but beyond the joint limit: only the limit clamps.
    wish = last.copy()
    wish[GRIPS] = 1.05
    sent = robot.send_action(wish)
    np.testing.assert_array_equal(sent[GRIPS], np.float32(1.0))
    np.testing.assert_allclose(sent[ARM], last[ARM], atol=1e-6)

    # Too fast: each joint moves at most max_joint_speed / control_rate per step, in either direction.
    last = robot.command().astype(np.float64)
    wish = last + np.tile([0.5, -0.5, 0.02, -0.02, 1.0, -1.0, -0.5], 2)
    sent = robot.send_action(wish)
    expected = np.clip(np.clip(wish, spec.lower_array, spec.upper_array), last - step, last + step)
    np.testing.assert_allclose(sent, expected, atol=1e-6)
    assert sent[0] == pytest.approx(last[0] + np.pi / 30, abs=1e-6)
    assert sent[1] == pytest.approx(last[1] - np.pi / 30, abs=1e-6)
    assert sent[2] == pytest.approx(last[2] + 0.02, abs=1e-6)  # slow enough: passed through
    assert sent[LEFT_GRIP] == pytest.approx(1.0 - 2.0 / 30, abs=1e-6)
    np.testing.assert_array_equal(robot.command(), sent)  # what was sent is what the servos track

    # Far beyond a joint limit: clamped to the limit, then rate-limited from the last command.
    last = robot.command().astype(np.float64)
    wish = last.copy()
    wish[2] = 100.0  # elbow, limit ±π
    sent = robot.send_action(wish)
    assert sent[2] == pytest.approx(min(spec.upper[2], last[2] + np.pi / 30), abs=1e-6)


# ---------------------------------------------------------------------- the privileged checker


@pytest.mark.parametrize("task", TASK_NAMES)
def test_check_subtask_at_starts_and_after_teleporting(robots: Callable[[str], SimRobot], task: str) -> None:
    robot = robots(task)
    for k in range(robot.task.num_subtasks):
        robot.reset(seed=5, subtask=k, history=0)
        if k > 0:
            prev = robot.check_subtask(k - 1)
            assert prev.success and prev.in_place and prev.released and prev.stable, prev.reason
        own = robot.check_subtask(k)
        assert not own.success and not own.in_place, own.reason
        assert robot.check_subtask() == own  # the current subtask by default
        assert robot.layout is not None
        robot.set_object_poses(robot.task.completed_poses(robot.layout, k + 1))
        done = robot.check_subtask(k)
        assert done.in_place and done.released, done.reason
        assert done.success, done.reason


@pytest.mark.parametrize("k", [0, 1])
def test_block_hovering_above_the_tower_is_not_placed(robots: Callable[[str], SimRobot], k: int) -> None:
    robot = robots("stack_blocks")
    robot.reset(seed=2, subtask=k, history=0)
    block = robot.task.geometry["block_red"].height
    top = robot.object_poses()[("block_red", "block_sky", "block_green")[k]]  # the tower's top block
    x, y, z = top.xyz
    name = robot.task.subtask_object(k)
    hover = z + block / 2 + 0.05 + block / 2  # its underside 5 cm above the tower top
    robot.set_object_poses({name: ObjectPose((x, y, hover), top.quat)})
    check = robot.check_subtask(k)
    assert not check.in_place and not check.stable and not check.success, check
    assert check.released
    assert "not resting on" in check.reason
    # The check ran on a copy: the block still hovers in the episode itself.
    assert robot.object_poses()[name].xyz[2] == pytest.approx(hover)


# ---------------------------------------------------------------------- determinism


def test_reset_is_deterministic(robots: Callable[[str], SimRobot]) -> None:
    robot = robots("stack_bowls")
    a = robot.reset(seed=11, subtask=1, history=2)
    layout_a = robot.layout
    robot.reset(seed=12, subtask=0, history=0)  # something else in between
    b = robot.reset(seed=11, subtask=1, history=2)
    assert robot.layout == layout_a
    for view in robot.spec.cameras:
        assert a.observation.images[view].tobytes() == b.observation.images[view].tobytes(), view
        for ha, hb in zip(a.history, b.history, strict=True):
            assert ha.images[view].tobytes() == hb.images[view].tobytes()
    np.testing.assert_array_equal(a.observation.state, b.observation.state)
    c = robot.reset(seed=13, subtask=1, history=0)
    assert robot.layout is not None and layout_a is not None
    assert robot.layout.poses != layout_a.poses
    assert c.observation.images["cam_high"].tobytes() != a.observation.images["cam_high"].tobytes()


@pytest.mark.parametrize("task", TASK_NAMES)
def test_layouts_differ_between_seeds_and_repeat_for_one(task: str) -> None:
    t = load_task(task)
    layouts = [t.layout(seed) for seed in range(5)]
    assert t.layout(3) == layouts[3]
    for name in layouts[0].poses:
        assert len({lay.poses[name].xyz for lay in layouts}) == 5, name


# ---------------------------------------------------------------------- argument errors


def test_unknown_task_names_the_choices() -> None:
    with pytest.raises(ValueError, match="no packaged task called 'juggling'") as info:
        SimRobot(SIM, "juggling")
    for name in TASK_NAMES:
        assert name in str(info.value)


@pytest.mark.parametrize("subtask", [-1, 3, True, 1.0, "0"])
def test_invalid_subtask_index_names_the_range(robots: Callable[[str], SimRobot], subtask: object) -> None:
    robot = robots("sort_cubes")
    with pytest.raises(ValueError, match=r"subtask: sort_cubes has subtasks 0\.\.2, got"):
        robot.reset(seed=0, subtask=subtask)  # type: ignore[arg-type]
    with pytest.raises(ValueError, match=r"subtask: sort_cubes has subtasks 0\.\.2, got"):
        robot.check_subtask(subtask)  # type: ignore[arg-type]


def test_invalid_subtask_index_for_a_two_subtask_task(robots: Callable[[str], SimRobot]) -> None:
    with pytest.raises(ValueError, match=r"stack_blocks has subtasks 0\.\.1, got 2"):
        robots("stack_blocks").reset(seed=0, subtask=2)


@pytest.mark.parametrize("seed", [1.5, "3", None, True])
def test_invalid_seed_is_refused(robots: Callable[[str], SimRobot], seed: object) -> None:
    with pytest.raises(ValueError, match="seed: expected an integer, got"):
        robots("sort_cubes").reset(seed=seed, subtask=0)  # type: ignore[arg-type]


def test_task_state_is_json_and_privileged(robots: Callable[[str], SimRobot]) -> None:
    import json

    robot = robots("sort_cubes")
    robot.reset(seed=2, subtask=1, history=0)
    state = json.loads(json.dumps(robot.task_state()))
    assert state["task"] == "sort_cubes" and state["seed"] == 2 and state["subtask"] == 1
    assert set(state["objects"]) == {"cube_small", "cube_medium", "cube_large"}
    assert state["placed"] == [True, False, False]  # subtask 0 was laid out as done
    assert all(v is None for v in state["held"].values())


def test_render_error_names_the_fix(monkeypatch: pytest.MonkeyPatch) -> None:
    from simrig import gl

    def broken(*args: object, **kwargs: object) -> None:
        raise RuntimeError("gladLoadGL error")

    monkeypatch.setattr(gl.mujoco, "Renderer", broken)
    with pytest.raises(gl.SimRenderError, match=r"libegl1.*MUJOCO_GL=osmesa"):
        gl.make_renderer(object(), 128, 128)


def test_reset_can_switch_task() -> None:
    with SimRobot(SIM, "sort_cubes") as robot:
        start = robot.reset(seed=1, subtask=1, task="stack_blocks", history=0)
        assert robot.task.name == "stack_blocks" and start.subtask.task == "stack_blocks"
        assert set(robot.object_poses()) == {"block_red", "block_sky", "block_green"}
        assert robot.check_subtask(0).success  # subtask 0 laid out as done
        with pytest.raises(ValueError, match=r"stack_bowls has subtasks 0\.\.2"):
            robot.reset(subtask=5, task="stack_bowls")
        assert robot.task.name == "stack_blocks"  # a refused switch leaves the robot as it was
        with pytest.raises(ValueError, match="history"):
            robot.reset(history=-1)
