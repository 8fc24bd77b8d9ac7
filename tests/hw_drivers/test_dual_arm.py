"""DualArmRobot on stand-in parts: the 14-d layout, guards, letterboxing, and stopping on any part's error."""

from __future__ import annotations

import time

import numpy as np
import pytest
from numpy.typing import NDArray

from hw_drivers.arm import ArmState
from hw_drivers.cameras.base import Frame
from hw_drivers.dual_arm import DualArmRobot, letterbox
from hw_drivers.errors import (
    DeviceAlreadyConnectedError,
    DeviceConnectionError,
    DeviceNotConnectedError,
    StaleObservationError,
)
from hw_drivers.grippers.base import GripperStatus
from pilworld.config.rig import RigConfig

SIM = "configs/rig/sim_dual_ur5e.yaml"


class StubArm:
    def __init__(self, name: str, q0: float) -> None:
        self.name = name
        self.is_connected = False
        self.q = np.full(6, q0)
        self.targets: list[NDArray[np.float64]] = []
        self.stops = 0
        self.fail_connect = False
        self.error: Exception | None = None

    def connect(self) -> None:
        if self.fail_connect:
            raise DeviceConnectionError(self.name, "no controller")
        self.is_connected = True

    def disconnect(self) -> None:
        self.is_connected = False

    def state(self, max_age: float = 0.1) -> ArmState:
        if self.error is not None:
            raise self.error
        return ArmState(q=self.q.copy(), qd=np.zeros(6), timestamp=time.monotonic(), safety="normal")

    def set_target(self, q: NDArray[np.floating]) -> None:
        self.targets.append(np.asarray(q, dtype=np.float64))

    def move_to(self, q: NDArray[np.floating], speed: float, timeout: float) -> None:
        self.q = np.asarray(q, dtype=np.float64).copy()

    def stop(self) -> None:
        self.stops += 1

    def recover(self) -> None:
        pass


class StubGripper:
    def __init__(self, name: str) -> None:
        self.name = name
        self.is_connected = False
        self.opening = 1.0
        self.targets: list[float] = []

    def connect(self) -> None:
        self.is_connected = True

    def disconnect(self) -> None:
        self.is_connected = False

    def set_target(self, opening: float) -> float:
        clipped = min(1.0, max(0.0, opening))
        self.targets.append(clipped)
        self.opening = clipped
        return clipped

    def status(self, max_age: float = 0.2) -> GripperStatus:
        return GripperStatus(self.opening, self.opening, False, "", time.monotonic())


class StubCamera:
    def __init__(self, name: str, size: tuple[int, int] = (128, 128), age: float = 0.0) -> None:
        self.name = name
        self.is_connected = False
        self.size = size
        self.age = age
        self.disconnects = 0

    def connect(self) -> None:
        self.is_connected = True

    def disconnect(self) -> None:
        self.is_connected = False
        self.disconnects += 1

    def read_latest(self, max_age: float = 0.2) -> Frame:
        if self.age > max_age:
            raise StaleObservationError(self.name, f"latest frame is {self.age:.2f} s old")
        w, h = self.size
        return Frame(np.full((h, w, 3), 200, np.uint8), time.monotonic() - self.age, 0)


def _robot(
    **camera_kw: object,
) -> tuple[DualArmRobot, dict[str, StubArm], dict[str, StubGripper], dict[str, StubCamera]]:
    spec = RigConfig.load(SIM).robot_spec()
    arms = {"left": StubArm("left arm", 0.1), "right": StubArm("right arm", -0.1)}
    grippers = {"left": StubGripper("left gripper"), "right": StubGripper("right gripper")}
    cameras = {c: StubCamera(c, **camera_kw) for c in spec.cameras}  # type: ignore[arg-type]
    return DualArmRobot(spec, arms, grippers, cameras), arms, grippers, cameras


def test_layout_and_what_was_sent() -> None:
    robot, arms, _, _ = _robot()
    with robot:
        obs = robot.observe()
        np.testing.assert_allclose(obs.state[:6], 0.1)
        np.testing.assert_allclose(obs.state[7:13], -0.1)
        assert obs.state[6] == obs.state[13] == 1.0
        a = np.arange(14, dtype=np.float64) / 10
        a[6], a[13] = 1.7, -0.3  # grips beyond 0 … 1: the grippers clip, and that is what is reported
        sent = robot.send_action(a)
        np.testing.assert_allclose(arms["left"].targets[-1], a[:6])
        np.testing.assert_allclose(arms["right"].targets[-1], a[7:13])
        assert sent[6] == 1.0 and sent[13] == 0.0 and sent.dtype == np.float32
    assert not robot.is_connected


def test_guards() -> None:
    robot, *_ = _robot()
    with pytest.raises(DeviceNotConnectedError):
        robot.observe()
    with pytest.raises(DeviceNotConnectedError):
        robot.send_action(np.zeros(14))
    with robot, pytest.raises(DeviceAlreadyConnectedError):
        robot.connect()
    robot.disconnect()  # idempotent


def test_a_failed_connect_disconnects_what_was_connected() -> None:
    robot, arms, _, cameras = _robot()
    arms["right"].fail_connect = True
    with pytest.raises(DeviceConnectionError, match="right arm"):
        robot.connect()
    assert not arms["left"].is_connected and not robot.is_connected
    assert not any(c.is_connected for c in cameras.values())


def test_any_part_error_stops_the_arms_first() -> None:
    robot, arms, _, _ = _robot()
    with robot:
        arms["left"].error = DeviceConnectionError("left arm", "connection lost")
        with pytest.raises(DeviceConnectionError, match="left arm"):
            robot.observe()
        assert arms["left"].stops >= 1 and arms["right"].stops >= 1


def test_stale_frames_are_refused() -> None:
    robot, arms, _, _ = _robot(age=1.0)
    with robot, pytest.raises(StaleObservationError):
        robot.observe()
    assert arms["right"].stops >= 1


def test_non_finite_commands_are_refused() -> None:
    robot, arms, _, _ = _robot()
    with robot:
        bad = np.zeros(14)
        bad[2] = np.nan
        with pytest.raises(ValueError, match="finite"):
            robot.send_action(bad)
        assert arms["left"].targets == [] and arms["left"].stops == 1


def test_camera_frames_are_letterboxed_to_the_rig_size() -> None:
    robot, *_ = _robot(size=(640, 480))
    with robot:
        img = robot.observe().images["cam_high"]
    assert img.shape == (128, 128, 3)
    assert img[:15].max() == 0 and img[-15:].max() == 0 and img[64, 64, 0] == 200  # 4:3 → bars top and bottom


def test_letterbox_keeps_aspect() -> None:
    out = letterbox(np.full((100, 200, 3), 9, np.uint8), (64, 64))
    assert out.shape == (64, 64, 3) and out[0].max() == 0 and out[32, 32, 0] == 9
