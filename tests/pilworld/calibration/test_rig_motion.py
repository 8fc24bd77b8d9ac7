"""Calibration moves on a hardware rig: path checks, the paced capped-speed profile, the plan and view files."""

from __future__ import annotations

import dataclasses
import json
from pathlib import Path

import numpy as np
import pytest

from calib.board import ChArUcoBoard
from hw_drivers.errors import SafetyViolationError
from hw_drivers.safety import SafetyFilter, dual_arm_speed_caps
from pilworld.calibration.recording import RecordedView, Recording
from pilworld.calibration.rig_collection import ArmPlan, CollectionPlan, ViewStore
from pilworld.calibration.rig_motion import MoveSettings, move_duration, paced_move, path_problem
from pilworld.config.rig import RigConfig
from simrig.poses import HOME_Q14

ROOT = Path(__file__).resolve().parents[3]
RIG = RigConfig.load(ROOT / "configs" / "rig" / "sim_dual_ur5e.yaml")
BOARD = ChArUcoBoard.from_yaml(ROOT / "configs" / "board" / "charuco_7x5_a4.yaml")
SPEC = dataclasses.replace(RIG.robot_spec(), max_joint_speed=dual_arm_speed_caps())


def test_settings_are_validated() -> None:
    with pytest.raises(ValueError, match="--speed"):
        MoveSettings(speed=2.0)
    with pytest.raises(ValueError, match="path_samples"):
        MoveSettings(path_samples=1)


def test_move_duration_caps_the_peak_joint_speed() -> None:
    s = MoveSettings(speed=0.5, min_duration_s=1.0)
    goal = HOME_Q14.copy()
    goal[0] += 1.0
    # A cosine profile over T peaks at π/2 · Δ/T: 1 rad at 0.5 rad/s needs π s.
    assert move_duration(HOME_Q14, goal, s) == pytest.approx(np.pi)
    assert move_duration(HOME_Q14, HOME_Q14, s) == 1.0
    grip_only = HOME_Q14.copy()
    grip_only[6] = 0.0
    assert move_duration(HOME_Q14, grip_only, s) == 1.0  # grippers do not set the pace


def test_path_problem_finds_the_table_and_the_other_arm() -> None:
    s = MoveSettings()
    assert path_problem(RIG.kinematics, HOME_Q14, HOME_Q14, s) is None
    down = HOME_Q14.copy()
    down[1] += 1.3  # the left shoulder swings the arm down into the table
    problem = path_problem(RIG.kinematics, HOME_Q14, down, s)
    assert problem is not None and "table" in problem and "of the way" in problem
    # Both arms reach into the middle: their capsules touch.
    across = np.array([0.71, -1.57, 2.19, -2.0, -1.57, 0.04, 1.0, -1.21, -3.11, 0.81, -2.0, -1.57, -0.28, 1.0])
    problem = path_problem(RIG.kinematics, HOME_Q14, across, s)
    assert problem is not None and "the two arms come within" in problem


class _Robot:
    """Records what it is sent; its measured state follows the commands exactly."""

    def __init__(self, q: np.ndarray) -> None:
        self.q = q.astype(np.float64).copy()
        self.sent: list[np.ndarray] = []

    def send_action(self, a: np.ndarray) -> np.ndarray:
        self.sent.append(np.asarray(a, dtype=np.float64))
        self.q = np.asarray(a, dtype=np.float64).copy()
        return self.q.astype(np.float32)

    def state(self) -> np.ndarray:
        return self.q.astype(np.float32)


def test_paced_move_streams_a_capped_profile_through_the_filter() -> None:
    goal = HOME_Q14.copy()
    goal[0] += 0.4
    robot = _Robot(HOME_Q14)
    safety = SafetyFilter(SPEC)
    safety.reset(HOME_Q14)
    t = {"now": 0.0}
    sleeps: list[float] = []

    def sleep(dt: float) -> None:
        sleeps.append(dt)
        t["now"] += dt

    s = MoveSettings(speed=0.5, settle_s=0.2)
    state = paced_move(robot, safety, HOME_Q14, goal, s, rate_hz=30.0, sleep=sleep, clock=lambda: t["now"])
    np.testing.assert_allclose(state, goal, atol=1e-6)
    steps = np.diff(np.array([q[0] for q in robot.sent]))
    assert np.max(np.abs(steps)) * 30.0 <= 0.5 + 1e-6  # never faster than --speed
    assert len(robot.sent) >= int(move_duration(HOME_Q14, goal, s) * 30) + int(0.2 * 30)  # profile, then the hold
    assert all(abs(dt - 1 / 30) < 1e-9 for dt in sleeps)  # paced at the control rate
    beyond = HOME_Q14.copy()
    beyond[5] = 7.0
    with pytest.raises(SafetyViolationError, match="joint_limits"):
        paced_move(robot, safety, state, beyond, s, rate_hz=30.0, sleep=sleep, clock=lambda: t["now"])


def test_plan_and_view_store_round_trip(tmp_path: Path) -> None:
    cmd = [HOME_Q14.tolist(), HOME_Q14.tolist()]
    plan = CollectionPlan("handeye", HOME_Q14.tolist(), [ArmPlan("left", cmd, "left arm: 2 poses")])
    plan.outcome["left_001"] = "skipped: no safe path"
    plan.save(tmp_path)
    again = CollectionPlan.load(tmp_path)
    assert again.pose_names(again.arms[0]) == ["left_000", "left_001"] and again.remaining() == 1
    assert again.outcome == plan.outcome and again.purpose == "handeye"
    with pytest.raises(FileNotFoundError, match="nothing to resume"):
        CollectionPlan.load(tmp_path / "none")
    store = ViewStore(
        tmp_path, "fake_dual_ur5e", BOARD, {"sim_truth": {"T_cam_base": np.eye(4).tolist(), "T_tcp_board": {}}}
    )
    image = np.full((48, 64, 3), 128, dtype=np.uint8)
    assert store.add(RecordedView("left_000", "left", image, HOME_Q14, HOME_Q14), "left_000") == "000.png"
    reopened = ViewStore(tmp_path, "fake_dual_ur5e", BOARD)
    assert reopened.count == 1  # a resumed collection appends after what is there
    assert reopened.add(RecordedView("left_002", "left", image, HOME_Q14), "left_002") == "001.png"
    rec = Recording.load(tmp_path)  # the format --from and check --images read
    assert [v.name for v in rec.views] == ["000.png", "001.png"] and rec.truth is not None
    assert json.loads((tmp_path / "poses.json").read_text())["views"][1]["pose"] == "left_002"
    assert not list(tmp_path.glob("*.tmp"))
