"""RobotiqGripper against the fake 2F-85 on a pty: activation, tracking, each fault → a typed error in bound."""

from __future__ import annotations

import math
import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager

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
from hw_drivers.fakes.faults import FaultSwitch
from hw_drivers.fakes.pty import PtyPair
from hw_drivers.fakes.robotiq import FakeRobotiqGripper
from hw_drivers.grippers.base import Gripper
from hw_drivers.grippers.robotiq import (
    RobotiqFaultError,
    RobotiqGripper,
    decode_fault,
    opening_to_position,
    position_to_opening,
)
from pilworld.types import ARM_LAYOUT, STATE_DIM

# The stated bound from an injected fault to the typed error, with the default timeout 0.1 s and
# retries 2: (1 + 2) × 0.1 s + one 20 ms poll period ≈ 0.32 s; asserted with margin for a busy CI box.
FAULT_BOUND = 1.0
# Outside the fault tests, a generous bus timeout: on a loaded 2-core CI box a scheduling hiccup of a
# few hundred ms must not read as a dead gripper. The fault tests use the driver's default on purpose.
CALM_TIMEOUT = 0.5
DEFAULT_TIMEOUT = 0.1


def backend_at(opening: float, grip_speed: float = 5.0) -> KinematicBackend:
    q0 = np.zeros(STATE_DIM)
    q0[ARM_LAYOUT["left"][1]] = opening
    return KinematicBackend(grip_speed=grip_speed, q0=q0)


@contextmanager
def rig(
    backend: KinematicBackend | None = None,
    *,
    closed_count: int = 255,
    activation_time: float = 0.02,
    timeout: float = CALM_TIMEOUT,
    **kw: object,
) -> Iterator[tuple[RobotiqGripper, FakeRobotiqGripper, KinematicBackend]]:
    backend = backend or backend_at(0.5)
    fake = FakeRobotiqGripper(
        backend, "left", faults=FaultSwitch(), activation_time=activation_time, closed_count=closed_count
    )
    with fake:
        gripper = RobotiqGripper("left_gripper", fake.path, timeout=timeout, **kw)  # type: ignore[arg-type]
        gripper.connect()
        try:
            yield gripper, fake, backend
        finally:
            gripper.disconnect()


def wait_for(cond: Callable[[], bool], timeout: float = 2.0) -> None:
    deadline = time.monotonic() + timeout
    while not cond():
        assert time.monotonic() < deadline, "condition not met in time"
        time.sleep(0.005)


def time_to_error(gripper: RobotiqGripper, bound: float = 3.0) -> tuple[RobotError, float]:
    """Seconds until ``status()`` raises something other than a stale reading, and the error."""
    t0 = time.monotonic()
    while time.monotonic() - t0 < bound:
        try:
            gripper.status(max_age=10.0)
        except RobotError as e:
            return e, time.monotonic() - t0
        time.sleep(0.002)
    raise AssertionError(f"no error within {bound} s")


# ------------------------------------------------------------------------------------------- pure functions


def test_opening_position_mapping() -> None:
    assert opening_to_position(1.0) == 0 and opening_to_position(0.0) == 255
    assert opening_to_position(0.5, 0, 230) == 115
    assert opening_to_position(2.0, 3, 230) == 3 and opening_to_position(-1.0, 3, 230) == 230  # clipped
    assert position_to_opening(0) == 1.0 and position_to_opening(255) == 0.0
    assert position_to_opening(115, 0, 230) == 0.5
    assert position_to_opening(240, 0, 230) == 0.0 and position_to_opening(1, 3, 230) == 1.0  # past the ends
    for p in range(3, 231):
        assert opening_to_position(position_to_opening(p, 3, 230), 3, 230) == p
    with pytest.raises(ValueError, match="position_open < position_closed"):
        opening_to_position(0.5, 200, 100)
    with pytest.raises(ValueError):
        position_to_opening(10, 0, 256)
    with pytest.raises(ValueError, match="finite"):
        opening_to_position(math.nan)
    with pytest.raises(ValueError):
        RobotiqGripper("g", "/dev/null", position_open=10, position_closed=10)
    with pytest.raises(ValueError, match="force"):
        RobotiqGripper("g", "/dev/null", force=300)


def test_fault_codes_decoded() -> None:
    assert decode_fault(0) == ""
    assert decode_fault(0x0A) == "0x0a: under minimum operating voltage"
    assert "automatic release completed" in decode_fault(0x0F)
    assert "overcurrent" in decode_fault(0x0E)
    assert decode_fault(0x03) == "0x03: unknown fault"
    assert decode_fault(0, kflt=2) == "controller fault kFLT 0x02"
    err = RobotiqFaultError("g", 0x0B)
    assert err.code == 0x0B and "automatic release in progress" in str(err)


# --------------------------------------------------------------------------------------------- lifecycle


def test_missing_port() -> None:
    g = RobotiqGripper("g", "/dev/ttyNOPE0")
    with pytest.raises(DeviceConnectionError, match="/dev/ttyNOPE0"):
        g.connect()
    assert not g.is_connected
    g.disconnect()


def test_silent_port_times_out_quickly() -> None:
    pair = PtyPair()  # nobody answers
    try:
        g = RobotiqGripper("g", pair.path, timeout=0.05, retries=1)
        t0 = time.monotonic()
        with pytest.raises(DeviceTimeoutError, match="no reply from slave 9"):
            g.connect()
        assert time.monotonic() - t0 < 0.5
        assert not g.is_connected
    finally:
        pair.close()


def test_activation_timeout() -> None:
    fake = FakeRobotiqGripper(backend_at(0.5), "left", activation_time=10.0)
    with fake:
        g = RobotiqGripper("g", fake.path, activation_timeout=0.2)
        with pytest.raises(DeviceTimeoutError, match="activation in progress"):
            g.connect()
        assert not g.is_connected


def test_fault_at_connect() -> None:
    fake = FakeRobotiqGripper(backend_at(0.5), "left", activation_time=0.02)
    fake.set_fault(0x0A, persistent=True)  # a reset does not clear low voltage
    with fake:
        g = RobotiqGripper("g", fake.path)
        with pytest.raises(RobotiqFaultError, match="under minimum operating voltage") as info:
            g.connect()
        assert info.value.code == 0x0A and not g.is_connected


def test_connect_activates_and_holds_position() -> None:
    with rig(backend_at(0.5)) as (g, fake, backend):
        assert isinstance(g, Gripper)
        assert bool(g.is_connected)  # bool(): keep mypy from narrowing the property for good
        assert fake.status_bytes()[0] >> 4 & 3 == 3  # gSTA activated
        st = g.status(1.0)
        assert st.opening == pytest.approx(0.5, abs=0.005) and st.target == st.opening
        time.sleep(0.1)
        # No start-up motion: the first goal is the measured position (at most one count of quantisation).
        assert abs(backend.gripper_opening("left") - 0.5) <= 1 / 255 + 1e-9
        with pytest.raises(DeviceAlreadyConnectedError):
            g.connect()
    g.disconnect()  # idempotent
    assert not g.is_connected
    with pytest.raises(DeviceNotConnectedError):
        g.status(1.0)
    with pytest.raises(DeviceNotConnectedError):
        g.set_target(0.3)


def test_not_connected_before_connect() -> None:
    g = RobotiqGripper("g", "/dev/null")
    with pytest.raises(DeviceNotConnectedError):
        g.set_target(0.5)
    with pytest.raises(DeviceNotConnectedError):
        g.status(1.0)
    assert math.isnan(g.roundtrip_ms().median_ms)


def test_reconnect() -> None:
    backend = backend_at(0.5)
    with FakeRobotiqGripper(backend, "left", activation_time=0.02) as fake:
        g = RobotiqGripper("g", fake.path)
        for target in (0.8, 0.2):
            with g:
                g.set_target(target)
                wait_for(lambda t=target: abs(g.status(1.0).opening - t) < 0.005)  # type: ignore[misc]


# ---------------------------------------------------------------------------------------------- tracking


def test_tracks_targets() -> None:
    with rig() as (g, _, backend):
        assert g.set_target(1.0) == 1.0
        wait_for(lambda: g.status(1.0).opening == 1.0)
        assert g.set_target(-0.5) == 0.0  # clipped
        wait_for(lambda: g.status(1.0).opening == 0.0)
        assert backend.gripper_opening("left") == 0.0
        g.set_target(0.3)
        wait_for(lambda: abs(g.status(1.0).opening - 0.3) < 0.005)
        st = g.status(1.0)
        assert st.target == 0.3 and not st.object_detected and st.fault == ""
        assert abs(backend.gripper_opening("left") - 0.3) < 0.005
        with pytest.raises(ValueError, match="finite"):
            g.set_target(math.nan)
        stats = g.roundtrip_ms()
        assert stats.count > 10 and 0 < stats.median_ms <= stats.p99_ms


def test_calibration_matches_a_230_count_stroke() -> None:
    with rig(closed_count=230, position_closed=230) as (g, _, backend):
        g.set_target(0.0)
        wait_for(lambda: g.status(1.0).opening == 0.0)
        g.set_target(0.5)
        wait_for(lambda: abs(backend.gripper_opening("left") - 0.5) < 1e-9)
        wait_for(lambda: g.status(1.0).opening == 0.5)


def test_object_detected() -> None:
    class Blocked(KinematicBackend):
        def gripper_opening(self, side: str) -> float:
            return max(0.4, super().gripper_opening(side))

    q0 = np.zeros(STATE_DIM)
    q0[ARM_LAYOUT["left"][1]] = 1.0
    with rig(Blocked(grip_speed=5.0, q0=q0)) as (g, _, _b):
        g.set_target(0.0)
        wait_for(lambda: g.status(1.0).object_detected)
        assert g.status(1.0).opening == pytest.approx(0.4, abs=0.005)
        g.set_target(1.0)
        wait_for(lambda: not g.status(1.0).object_detected)


def test_intermittent_drops_are_absorbed_by_retries() -> None:
    with rig(retries=6, timeout=DEFAULT_TIMEOUT) as (g, fake, _):
        fake.faults.inject("drop", rate=0.2)
        fake.faults.inject("corrupt", rate=0.1)
        for target in (1.0, 0.0, 0.6):
            g.set_target(target)
            wait_for(lambda t=target: abs(g.status(1.0).opening - t) < 0.005)  # type: ignore[misc]
        assert g.is_connected


def test_minor_fault_reported_not_raised() -> None:
    with rig() as (g, fake, _):
        fake.set_fault(0x09)  # communication watchdog: informational
        wait_for(lambda: "no communication" in g.status(1.0).fault)
        g.set_target(0.9)
        assert g.is_connected


# ------------------------------------------------------------------------------------------------ faults


@pytest.mark.parametrize(
    ("kind", "error"),
    [
        ("drop", DeviceTimeoutError),
        ("stall", DeviceTimeoutError),
        ("corrupt", DeviceProtocolError),
        ("disconnect", DeviceConnectionError),
    ],
)
def test_bus_fault_becomes_typed_error_in_bound(kind: str, error: type[RobotError]) -> None:
    with rig(timeout=DEFAULT_TIMEOUT) as (g, fake, _):
        g.status()
        fake.faults.inject(kind)
        err, elapsed = time_to_error(g)
        assert type(err) is error, err
        assert err.device == "left_gripper"
        assert elapsed < FAULT_BOUND
        assert not g.is_connected
        with pytest.raises(error):
            g.set_target(0.1)  # every later call raises the stored error


@pytest.mark.parametrize("code", [0x08, 0x0A, 0x0B, 0x0C, 0x0D, 0x0E, 0x0F])
def test_device_fault_becomes_typed_error(code: int) -> None:
    with rig(timeout=DEFAULT_TIMEOUT) as (g, fake, _):
        fake.set_fault(code)
        err, elapsed = time_to_error(g)
        assert isinstance(err, RobotiqFaultError) and err.code == code, err
        assert decode_fault(code) in str(err)
        assert elapsed < FAULT_BOUND  # typically the next status poll (20 ms period)


def test_lost_activation_is_a_fault() -> None:
    with rig(timeout=DEFAULT_TIMEOUT) as (g, fake, _):
        fake.power_cycle()
        err, elapsed = time_to_error(g)
        assert isinstance(err, DeviceFaultError) and "no longer activated (gSTA: reset)" in str(err)
        assert elapsed < FAULT_BOUND


def test_set_target_never_blocks_while_the_bus_stalls() -> None:
    # An ordering, not a speed: with retries=100 the I/O thread retries its stalled request for ~10 s
    # (101 × 0.1 s). Were set_target to wait on the bus, 200 calls would outlast those retries and end in
    # the stored DeviceTimeoutError. So every call returns while the gripper is merely stale, and when the
    # bus answers again the last target is the one driven.
    with rig(retries=100, timeout=DEFAULT_TIMEOUT) as (g, fake, backend):
        fake.faults.inject("stall")
        targets = [0.2 + 0.6 * i / 199 for i in range(200)]
        for t in targets:
            assert g.set_target(t) == pytest.approx(t)
        time.sleep(0.3)  # let the last reading age past max_age
        with pytest.raises(StaleObservationError):  # still retrying, no timeout error yet
            g.status(max_age=0.1)
        fake.faults.clear("stall")
        wait_for(lambda: abs(g.status(1.0).opening - targets[-1]) < 0.01, timeout=5.0)
        assert abs(backend.gripper_opening("left") - targets[-1]) < 0.01


def test_status_goes_stale_while_retrying() -> None:
    with rig(retries=5, timeout=DEFAULT_TIMEOUT) as (
        g,
        fake,
        _,
    ):  # the error comes after 6 × 0.1 s; staleness long before
        fake.faults.inject("stall")
        time.sleep(0.15)
        with pytest.raises(StaleObservationError, match="old"):
            g.status(max_age=0.05)
