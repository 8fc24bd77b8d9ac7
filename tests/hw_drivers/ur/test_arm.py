"""URArm against the fake UR controller (in its own process) through the real ur_rtde client (in URArm's worker)."""

from __future__ import annotations

import os
import signal
import time
from collections.abc import Iterator

import numpy as np
import pytest

from hw_drivers.arm import Arm
from hw_drivers.errors import (
    DeviceAlreadyConnectedError,
    DeviceConnectionError,
    DeviceFaultError,
    DeviceNotConnectedError,
    DeviceProtocolError,
    DeviceTimeoutError,
    EmergencyStopError,
    ProtectiveStopError,
    RobotError,
    StaleObservationError,
)
from hw_drivers.ur.arm import URArm
from tests.hw_drivers.ur.fake_process import FakeURProcess, random_host

pytestmark = pytest.mark.timeout(60)

FAR = np.array([1.5, -1.0, 1.0, 0.5, -0.5, 0.3])


@pytest.fixture
def fake() -> Iterator[FakeURProcess]:
    with FakeURProcess() as f:
        yield f


@pytest.fixture
def arm(fake: FakeURProcess) -> Iterator[URArm]:
    a = URArm("left", fake.host, connect_timeout=5.0, retries=1)
    a.connect()
    yield a
    a.disconnect()


def wait_for(arm: URArm, goal: np.ndarray, timeout: float = 3.0, tol: float = 2e-3) -> None:
    deadline = time.monotonic() + timeout
    while np.max(np.abs(arm.state().q - goal)) > tol:
        assert time.monotonic() < deadline, f"arm at {arm.state().q}, expected {goal}"
        time.sleep(0.01)


def test_connect_and_read(arm: URArm, fake: FakeURProcess) -> None:
    assert isinstance(arm, Arm) and arm.is_connected and arm.name == "left"
    s = arm.state()
    np.testing.assert_allclose(s.q, fake.status()["q"], atol=1e-6)
    assert s.safety == "normal" and time.monotonic() - s.timestamp < 0.1
    with pytest.raises(DeviceAlreadyConnectedError):
        arm.connect()


def test_state_tracks_set_target(arm: URArm, fake: FakeURProcess) -> None:
    goal = np.array([0.2, -0.1, 0.15, 0.0, 0.05, -0.2])
    for k in range(1, 21):  # a 10 Hz policy streaming small steps
        arm.set_target(goal * k / 20)
        time.sleep(0.02)
    wait_for(arm, goal)
    np.testing.assert_allclose(fake.status()["q"], goal, atol=2e-3)
    with pytest.raises(ValueError):
        arm.set_target(np.array([0.0, np.nan, 0, 0, 0, 0]))


def test_move_to_caps_speed(arm: URArm, fake: FakeURProcess) -> None:
    goal = np.array([0.5, 0.25, -0.25, 0.0, 0.0, 0.1])
    t0 = time.monotonic()
    arm.move_to(goal, speed=0.5, timeout=30.0)
    took = time.monotonic() - t0
    # The largest joint moves 0.5 rad at no more than 0.5 rad/s: the move cannot take less than 1 s. It may
    # take longer (a late servo cycle moves less, never faster), so there is no upper bound but the timeout.
    assert took >= 0.5 / 0.5 * 0.97
    np.testing.assert_allclose(arm.state().q, goal, atol=2e-3)


def test_move_to_timeout_stops_the_arm(arm: URArm, fake: FakeURProcess) -> None:
    with pytest.raises(DeviceTimeoutError):
        arm.move_to(FAR, speed=0.5, timeout=0.3)
    still = fake.wait_still()
    assert 0.05 < still["q"][0] < 0.5  # stopped partway, not at the goal


def test_servo_stats_are_consistent(arm: URArm) -> None:
    # The achieved rate and jitter are benchmark figures (pilworld bench drivers), not assertions here:
    # this checks that the loop runs and the statistics describe the same cycles.
    arm.reset_servo_stats()
    arm.set_target(np.full(6, 0.3))
    time.sleep(0.5)
    stats = arm.servo_stats()
    assert stats.cycles > 0 and stats.window_s > 0, stats
    assert stats.rate_hz == pytest.approx(stats.cycles / stats.window_s, rel=0.05), stats
    assert 0 < stats.period_p50_ms <= stats.period_p99_ms <= stats.period_max_ms, stats
    assert 0 <= stats.missed_periods <= stats.cycles, stats


# fault, expected error, bound [s] from injection to the error (stream faults: stream_timeout 0.5 s + slack)
FAULTS = [
    ("drop", DeviceTimeoutError, 1.5),
    ("stall", DeviceTimeoutError, 1.5),
    ("corrupt", DeviceProtocolError, 0.5),
    ("disconnect", DeviceConnectionError, 1.5),
    ("protective_stop", ProtectiveStopError, 0.5),
    ("emergency_stop", EmergencyStopError, 0.5),
]


@pytest.mark.parametrize(("kind", "error", "bound"), FAULTS, ids=[f[0] for f in FAULTS])
def test_fault_raises_typed_error_stops_and_recovers(
    arm: URArm, fake: FakeURProcess, kind: str, error: type[RobotError], bound: float
) -> None:
    arm.set_target(FAR)  # moving when the fault strikes
    time.sleep(0.2)
    fake.inject(kind)
    t0 = time.monotonic()
    if kind == "drop":
        time.sleep(0.15)
        with pytest.raises(StaleObservationError):
            arm.state(max_age=0.1)  # stale before the stream is declared dead
    while True:
        try:
            arm.state(max_age=10.0)
        except error:
            break
        assert time.monotonic() - t0 < bound, f"no {error.__name__} within {bound} s"
        time.sleep(0.005)
    took = time.monotonic() - t0
    assert took < bound
    with pytest.raises(error):
        arm.set_target(np.zeros(6))  # every later call raises too, until recover()
    if kind != "stall":  # a stalled controller runs nothing, not even its watchdog
        status = fake.wait_still()
        assert not status["program_running"], status  # the watchdog or the safety system stopped the script
        assert status["q"][0] < FAR[0] - 0.1  # stopped on the way
    fake.clear(kind)
    if kind == "stall":
        fake.wait_still()
    if kind == "emergency_stop":
        fake.inject("emergency_stop")
        with pytest.raises(EmergencyStopError):
            arm.recover()  # never released by software
        fake.clear("emergency_stop")
        while fake.status()["safety"] == "emergency_stop":  # the operator released it
            time.sleep(0.01)
    arm.recover()
    assert arm.state().safety == "normal"
    here = arm.state().q
    arm.set_target(here + 0.05)
    wait_for(arm, here + 0.05)


def test_worker_killed_watchdog_stops_arm(arm: URArm, fake: FakeURProcess) -> None:
    arm.set_target(FAR)
    time.sleep(0.2)
    assert arm._proc is not None
    arm._proc.kill()
    t0 = time.monotonic()
    with pytest.raises(DeviceConnectionError):
        while time.monotonic() - t0 < 2.0:
            arm.state(max_age=10.0)
            time.sleep(0.005)
    status = fake.wait_still()
    assert not status["program_running"] and status["q"][0] < FAR[0] - 0.1


def test_a_paused_servo_loop_is_named_as_the_cause_of_the_watchdog_stop(arm: URArm, fake: FakeURProcess) -> None:
    # This computer, not the controller, is at fault when the servo process cannot run for longer than the
    # watchdog allows (0.1 s here): the error says so, with the pause, so a user looks at their PC's load.
    assert arm._proc is not None and arm._proc.pid is not None
    arm.set_target(FAR)
    time.sleep(0.2)
    os.kill(arm._proc.pid, signal.SIGSTOP)
    time.sleep(0.4)
    os.kill(arm._proc.pid, signal.SIGCONT)
    t0 = time.monotonic()
    with pytest.raises(DeviceFaultError) as caught:
        while time.monotonic() - t0 < 5.0:
            arm.state(max_age=10.0)
            time.sleep(0.005)
    message = str(caught.value)
    assert "watchdog" in message and "the servo loop itself paused for" in message, message
    paused = float(message.split("paused for ")[1].split(" s")[0])
    assert paused >= 0.35, message
    assert not fake.wait_still()["program_running"]
    arm.recover()
    here = arm.state().q
    arm.set_target(here + 0.05)
    wait_for(arm, here + 0.05)


def test_a_paused_fake_controller_does_not_blame_the_client(arm: URArm, fake: FakeURProcess) -> None:
    # The fake's threads share one interpreter: after the whole fake process paused (a loaded machine), its
    # control thread may run before its RTDE thread has applied the kicks that arrived meanwhile. Those
    # kicks were on time, so the watchdog (0.1 s) must not stop the program; 0.3 s stays inside the
    # client's stream_timeout (0.5 s).
    assert fake._proc is not None and fake._proc.pid is not None
    arm.set_target(FAR)
    time.sleep(0.2)
    for _ in range(3):
        os.kill(fake._proc.pid, signal.SIGSTOP)
        time.sleep(0.3)
        os.kill(fake._proc.pid, signal.SIGCONT)
        time.sleep(0.3)
        arm.state(max_age=10.0)  # no fault: raises if the script stopped
    assert fake.status()["program_running"]


def test_connect_to_nothing_fails_fast() -> None:
    arm = URArm("left", random_host(), connect_timeout=2.0, retries=2)
    t0 = time.monotonic()
    with pytest.raises(DeviceConnectionError, match="left"):
        arm.connect()
    assert time.monotonic() - t0 < 3.0
    assert not arm.is_connected


def test_disconnect_is_idempotent_and_stops(fake: FakeURProcess) -> None:
    arm = URArm("right", fake.host)
    with arm:
        arm.set_target(FAR)
        time.sleep(0.2)
    status = fake.wait_still()
    assert not status["program_running"] and not status["servoing"]
    arm.disconnect()
    with pytest.raises(DeviceNotConnectedError):
        arm.state()
    arm.stop()  # safe in any state
