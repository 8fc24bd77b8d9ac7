"""``DynamixelGripper`` with the real ``dynamixel_sdk`` against the fake bus on a pty.

Fault bounds asserted here: every fault → its typed error in < FAULT_BOUND s, and ``set_target`` never
waits on the bus. With the driver's defaults (retries=2, timeout=0.04 s, 100 Hz) no answer takes ~0.15 s,
corruption and hang-up a few ms, a hardware error ≤ 0.1 s + one read. The tests run with timeout=0.15 s
(~0.45 s to a timeout error) and read status with max_age=AGE so that CPU contention on a shared CI
machine (the fake and the driver share the cores) is not mistaken for a fault.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Iterator
from pathlib import Path

import numpy as np
import pytest

from hw_drivers.errors import (
    DeviceAlreadyConnectedError,
    DeviceConnectionError,
    DeviceFaultError,
    DeviceNotConnectedError,
    DeviceProtocolError,
    DeviceTimeoutError,
    RobotError,
    StaleObservationError,
)
from hw_drivers.fakes.backend import KinematicBackend
from hw_drivers.fakes.dynamixel_bus import INST_SYNC_WRITE, FakeDynamixelBus
from hw_drivers.fakes.faults import FaultSwitch
from hw_drivers.grippers.base import Gripper
from hw_drivers.grippers.dynamixel import DynamixelGripper
from pilworld.types import LEFT_GRIP, STATE_DIM

FAULT_BOUND = 1.0  # s, fault injected → typed error raised by the next call
CLOSED, OPEN = 2048, 3072  # the fake's own mapping (FakeDynamixelBus defaults)
TIMEOUT = 0.15  # s per status packet in these tests (see the module docstring)
AGE = 1.0  # max_age of status() where staleness is not the point


class Rig:
    def __init__(self, backend: KinematicBackend, faults: FaultSwitch, bus: FakeDynamixelBus) -> None:
        self.backend, self.faults, self.bus = backend, faults, bus

    def gripper(self, **kw: object) -> DynamixelGripper:
        args: dict[str, object] = {"ticks_closed": CLOSED, "ticks_open": OPEN, "timeout": TIMEOUT, **kw}
        return DynamixelGripper("left_gripper", self.bus.path, 1, **args)  # type: ignore[arg-type]


def _backend(opening: float = 0.5, cls: type[KinematicBackend] = KinematicBackend) -> KinematicBackend:
    q0 = np.zeros(STATE_DIM)
    q0[LEFT_GRIP] = opening
    return cls(q0=q0, grip_speed=5.0)


@pytest.fixture
def rig() -> Iterator[Rig]:
    backend, faults = _backend(), FaultSwitch()
    with FakeDynamixelBus(backend, {1: "left"}, faults) as bus:
        yield Rig(backend, faults, bus)


@pytest.fixture
def gripper(rig: Rig) -> Iterator[DynamixelGripper]:
    g = rig.gripper()
    g.connect()
    yield g
    g.disconnect()


def _until(cond: Callable[[], bool], timeout: float = 2.0) -> None:
    deadline = time.monotonic() + timeout
    while not cond():
        assert time.monotonic() < deadline, "condition not met in time"
        time.sleep(0.005)


def _time_to_error(g: DynamixelGripper) -> tuple[RobotError, float]:
    t0 = time.monotonic()
    while time.monotonic() - t0 < 5.0:
        try:
            g.status(max_age=5.0)
        except RobotError as e:
            return e, time.monotonic() - t0
        time.sleep(0.001)
    raise AssertionError("no error within 5 s")


# ------------------------------------------------------------------------------------------- tracking


def test_is_a_gripper(gripper: DynamixelGripper) -> None:
    assert isinstance(gripper, Gripper)
    assert gripper.is_connected and gripper.name == "left_gripper"


def test_tracks_targets(rig: Rig, gripper: DynamixelGripper) -> None:
    first = gripper.status(AGE)
    assert first.opening == pytest.approx(0.5) and first.target == pytest.approx(0.5)
    for target in (0.9, 0.1, 0.6):
        assert gripper.set_target(target) == target
        _until(lambda t=target: abs(gripper.status(AGE).opening - t) < 0.002)  # type: ignore[misc]
        assert rig.backend.gripper_opening("left") == pytest.approx(target, abs=0.002)
        assert gripper.status(AGE).target == pytest.approx(target, abs=0.001)
    assert gripper.set_target(1.7) == 1.0 and gripper.set_target(-3.0) == 0.0
    _until(lambda: gripper.status(AGE).opening < 0.002)
    with pytest.raises(ValueError):
        gripper.set_target(float("nan"))


def test_reversed_calibration() -> None:
    backend = _backend(0.5)
    with FakeDynamixelBus(backend, {1: "left"}, ticks_closed=3000, ticks_open=1000) as bus:
        g = DynamixelGripper("g", bus.path, 1, ticks_closed=3000, ticks_open=1000, timeout=TIMEOUT)
        with g:
            assert g.status(AGE).opening == pytest.approx(0.5)
            g.set_target(0.8)
            _until(lambda: abs(backend.gripper_opening("left") - 0.8) < 0.002)
            assert bus.register(1, "Goal_Position") == 1400


def test_writes_the_goal_only_when_it_changes(rig: Rig, gripper: DynamixelGripper) -> None:
    time.sleep(0.1)
    assert rig.bus.instructions[INST_SYNC_WRITE] == 0  # nothing asked yet: the servo holds its goal
    for _ in range(20):
        gripper.set_target(0.7)
    _until(lambda: rig.bus.instructions[INST_SYNC_WRITE] >= 1)
    _until(lambda: abs(gripper.status(AGE).opening - 0.7) < 0.002)
    time.sleep(0.1)  # ~10 more cycles with the goal confirmed: nothing more to write
    assert rig.bus.instructions[INST_SYNC_WRITE] == 1


def test_a_dropped_goal_write_is_repeated(rig: Rig, gripper: DynamixelGripper) -> None:
    rig.faults.inject("drop", rate=0.3)  # seed 0: some packets vanish, 3 in a row only at the 72nd
    gripper.set_target(0.2)
    _until(lambda: rig.bus.register(1, "Goal_Position") == round(CLOSED + 0.2 * (OPEN - CLOSED)))
    rig.faults.clear()
    _until(lambda: abs(gripper.status(AGE).opening - 0.2) < 0.002)


def test_survives_occasional_corruption(rig: Rig) -> None:
    # FaultSwitch(seed=0) at rate 0.25 first corrupts 3 replies in a row at its 130th draw: the retries
    # absorb everything before it, and the ~40 polls below draw far fewer than that.
    g = rig.gripper()
    with g:
        rig.faults.inject("corrupt", rate=0.25)
        g.set_target(0.3)
        time.sleep(0.3)
        assert g.status(AGE).opening == pytest.approx(0.3, abs=0.002)


def test_startup_writes_present_to_goal_before_torque_on(rig: Rig) -> None:
    rig.bus.set_register(1, "Goal_Position", CLOSED)  # a previous session left the goal at closed
    rig.bus.set_register(1, "Torque_Enable", 0)
    g = rig.gripper(current_limit_ma=400.0)
    with g:
        assert rig.bus.writes(1) == [
            ("Torque_Enable", 0),
            ("Operating_Mode", 5),
            ("Goal_Current", round(400 / 2.69)),
            ("Goal_Position", 2560),  # where the fingers stand (opening 0.5)
            ("Torque_Enable", 1),
        ]
        time.sleep(0.2)
        assert rig.backend.gripper_opening("left") == pytest.approx(0.5)  # no jump to the stale goal
        assert g.status(AGE).target == pytest.approx(0.5)


def test_object_detected_when_the_fingers_stop_short() -> None:
    class Blocked(KinematicBackend):
        def gripper_opening(self, side: str) -> float:
            return max(0.4, super().gripper_opening(side))

    with FakeDynamixelBus(_backend(0.8, Blocked), {1: "left"}) as bus:
        g = DynamixelGripper("g", bus.path, 1, ticks_closed=CLOSED, ticks_open=OPEN, timeout=TIMEOUT)
        with g:
            assert not g.status(AGE).object_detected
            g.set_target(0.6)
            _until(lambda: abs(g.status(AGE).opening - 0.6) < 0.002)
            time.sleep(0.1)
            assert not g.status(AGE).object_detected  # reached the goal: nothing held
            g.set_target(0.0)
            _until(lambda: g.status(AGE).object_detected)
            assert g.status(AGE).opening == pytest.approx(0.4, abs=0.002)


def test_roundtrip_stats(gripper: DynamixelGripper) -> None:
    time.sleep(0.3)
    stats = gripper.roundtrip_ms()
    assert stats.count >= 20
    assert 0 < stats.median_ms < 5 and stats.median_ms <= stats.p99_ms


# ------------------------------------------------------------------------------------------- faults


@pytest.mark.parametrize(
    ("kind", "error"),
    [
        ("drop", DeviceTimeoutError),
        ("stall", DeviceTimeoutError),
        ("corrupt", DeviceProtocolError),
        ("disconnect", DeviceConnectionError),
    ],
)
def test_fault_to_typed_error_in_bounded_time(
    rig: Rig, gripper: DynamixelGripper, kind: str, error: type[RobotError]
) -> None:
    rig.faults.inject(kind)
    err, elapsed = _time_to_error(gripper)
    assert isinstance(err, error), repr(err)
    assert elapsed < FAULT_BOUND
    assert err.device == "left_gripper"
    with pytest.raises(error):
        gripper.set_target(0.3)
    assert not gripper.is_connected
    t0 = time.monotonic()
    gripper.disconnect()  # best effort on a broken bus, still quick
    assert time.monotonic() - t0 < 0.5


def test_hardware_error_is_a_fault(rig: Rig, gripper: DynamixelGripper) -> None:
    rig.bus.set_hardware_error(1)
    err, elapsed = _time_to_error(gripper)
    assert isinstance(err, DeviceFaultError) and "overload" in str(err)
    assert elapsed < FAULT_BOUND


def test_set_target_never_waits_on_a_stalled_bus(rig: Rig) -> None:
    # An ordering, not a speed: with retries=100 the I/O thread keeps retrying its first stalled status read
    # for ~15 s (100 × TIMEOUT). Were set_target to wait on the bus (or on a lock the I/O thread holds
    # across a transaction), 200 calls would take ≥ 200 bus timeouts and the retries would run out first,
    # turning the calls into DeviceTimeoutError. So: every call returns while the gripper is still merely
    # stale, and once the bus answers again the last target is the one that is driven.
    g = rig.gripper(retries=100)
    with g:
        rig.faults.inject("stall")
        targets = [0.2 + 0.6 * i / 199 for i in range(200)]
        for t in targets:
            assert g.set_target(t) == pytest.approx(t)
        time.sleep(0.3)  # let the last reading age past max_age
        with pytest.raises(StaleObservationError):  # still retrying the first stalled read, no timeout yet
            g.status(max_age=0.1)
        writes_before = len(rig.bus.writes(1))
        rig.faults.clear("stall")
        _until(lambda: abs(g.status(AGE).opening - targets[-1]) < 0.002, timeout=5.0)
        assert abs(rig.backend.gripper_opening("left") - targets[-1]) < 0.002
        # Only the latest target reached the bus: far fewer goal writes than set_target calls.
        assert len(rig.bus.writes(1)) - writes_before < len(targets) // 4


# ---------------------------------------------------------------------------------- connect / refuse


def test_wrong_model_is_refused() -> None:
    with FakeDynamixelBus(_backend(), {1: "left"}, model=1060) as bus:
        g = DynamixelGripper("g", bus.path, 1, ticks_closed=CLOSED, ticks_open=OPEN, timeout=TIMEOUT)
        with pytest.raises(DeviceConnectionError, match=r"model 1060 \(XL430-W250\), expected 1020"):
            g.connect()
        assert not g.is_connected
        assert bus.writes(1) == []  # refused before touching anything


def test_missing_port(tmp_path: Path) -> None:
    path = str(tmp_path / "ttyUSB9")
    g = DynamixelGripper("g", path, 1, ticks_closed=CLOSED, ticks_open=OPEN)
    with pytest.raises(DeviceConnectionError, match="ttyUSB9"):
        g.connect()
    g.disconnect()  # nothing to release


def test_absent_servo_id(rig: Rig) -> None:
    g = DynamixelGripper("g", rig.bus.path, 5, ticks_closed=CLOSED, ticks_open=OPEN, timeout=TIMEOUT)
    with pytest.raises(DeviceConnectionError, match=r"servo 5 .* does not answer ping"):
        g.connect()


def test_hardware_error_at_connect(rig: Rig) -> None:
    rig.bus.set_hardware_error(1)
    with pytest.raises(DeviceFaultError, match="overload"):
        rig.gripper().connect()


def test_configuration_beyond_the_servo_is_refused(rig: Rig) -> None:
    with pytest.raises(DeviceConnectionError, match="Current_Limit"):
        rig.gripper(current_limit_ma=5000.0).connect()
    with pytest.raises(DeviceConnectionError, match="outside the calibrated travel"):
        rig.gripper(ticks_closed=100, ticks_open=1000).connect()  # the fingers stand at 2560
    assert rig.bus.register(1, "Torque_Enable") == 0


def test_lifecycle_guards(rig: Rig) -> None:
    g = rig.gripper()
    with pytest.raises(DeviceNotConnectedError):
        g.set_target(0.5)
    with pytest.raises(DeviceNotConnectedError):
        g.status()
    g.connect()
    with pytest.raises(DeviceAlreadyConnectedError):
        g.connect()
    g.disconnect()
    g.disconnect()  # idempotent
    assert rig.bus.register(1, "Torque_Enable") == 0
    assert not g.is_connected
    g.connect()  # and again
    assert g.status(AGE).opening == pytest.approx(0.5)
    g.disconnect()


def test_constructor_validation() -> None:
    with pytest.raises(ValueError, match="must differ"):
        DynamixelGripper("g", "/dev/null", 1, ticks_closed=100, ticks_open=100)
    with pytest.raises(ValueError, match="baudrate"):
        DynamixelGripper("g", "/dev/null", 1, ticks_closed=0, ticks_open=100, baudrate=12345)
    with pytest.raises(ValueError, match="servo_id"):
        DynamixelGripper("g", "/dev/null", 254, ticks_closed=0, ticks_open=100)
