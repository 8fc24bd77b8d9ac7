"""The fake Robotiq 2F-85, spoken to byte by byte (the manual's frames) over its pty."""

from __future__ import annotations

import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager

import pytest
import serial

from hw_drivers.fakes.backend import KinematicBackend
from hw_drivers.fakes.faults import FaultSwitch
from hw_drivers.fakes.robotiq import RELEASED_OPENING, FakeRobotiqGripper
from hw_drivers.grippers import modbus


def h(s: str) -> bytes:
    return bytes.fromhex(s)


class Rig:
    def __init__(self, fake: FakeRobotiqGripper, backend: KinematicBackend) -> None:
        self.fake, self.backend = fake, backend
        self.port = serial.Serial(fake.path, 115200, timeout=1.0)  # generous: a loaded CI box

    def ask(self, frame: bytes, n: int = 64) -> bytes:
        self.port.reset_input_buffer()
        self.port.write(frame)
        return bytes(self.port.read(n))

    def silent(self, frame: bytes) -> bool:
        """Whether ``frame`` gets no reply within 0.2 s."""
        self.port.reset_input_buffer()
        self.port.write(frame)
        time.sleep(0.2)
        return int(self.port.in_waiting) == 0

    def command(self, action: int, position: int = 0, speed: int = 255, force: int = 255) -> bytes:
        regs = modbus.bytes_to_registers(bytes([action, 0, 0, position, speed, force]))
        return self.ask(modbus.write_request(9, 1000, regs), 8)

    def status(self, function: int = modbus.READ_HOLDING) -> bytes:
        reply = self.ask(modbus.read_request(9, 2000, 3, function), 11)
        return modbus.parse_reply(reply, slave=9, function=function)

    def activate(self) -> None:
        self.command(0)
        self.command(0x01)
        wait_for(lambda: self.status()[0] >> 4 & 3 == 3)


def wait_for(cond: Callable[[], bool], timeout: float = 2.0) -> None:
    deadline = time.monotonic() + timeout
    while not cond():
        assert time.monotonic() < deadline, "condition not met in time"
        time.sleep(0.01)


@contextmanager
def make_rig(backend: KinematicBackend | None = None, **kw: object) -> Iterator[Rig]:
    backend = backend or KinematicBackend(grip_speed=5.0)
    fake = FakeRobotiqGripper(backend, "left", faults=FaultSwitch(), **kw)  # type: ignore[arg-type]
    with fake:
        rig = Rig(fake, backend)
        try:
            yield rig
        finally:
            rig.port.close()


@pytest.fixture
def rig() -> Iterator[Rig]:
    with make_rig(activation_time=0.05) as r:
        yield r


def test_manual_activation_sequence() -> None:
    with make_rig(activation_time=0.5) as r:
        assert r.ask(h("09 10 03 E8 00 03 06 00 00 00 00 00 00 73 30"), 8) == h("09 10 03 E8 00 03 01 30")
        assert r.ask(h("09 10 03 E8 00 03 06 01 00 00 00 00 00 72 E1"), 8) == h("09 10 03 E8 00 03 01 30")
        assert r.ask(h("09 03 07 D0 00 01 85 CF"), 7) == h("09 03 02 11 00 55 D5")  # activating
        t0 = time.monotonic()
        wait_for(lambda: r.ask(h("09 03 07 D0 00 01 85 CF"), 7) == h("09 03 02 31 00 4C 15"))
        assert 0.3 < time.monotonic() - t0 < 2.0  # takes a realistic moment


def test_moves_the_backend_and_reports_position(rig: Rig) -> None:
    rig.activate()
    rig.command(0x09, position=255)
    wait_for(lambda: rig.backend.gripper_opening("left") == 0.0)
    wait_for(lambda: rig.status()[0] >> 6 == 3)  # gOBJ 3: at the requested position
    st = rig.status(modbus.READ_INPUT)  # FC04 reads the same registers
    assert st[0] == 0x01 | 0x08 | 0x30 | 0xC0 and (st[3], st[4]) == (255, 255)
    rig.command(0x09, position=0)
    wait_for(lambda: rig.status()[4] == 0)
    assert rig.backend.gripper_opening("left") == 1.0
    rig.command(0x09, position=102)  # 1 - 102/255 = 0.6
    wait_for(lambda: rig.status()[0] >> 6 == 3)  # "at the requested position": within 2 counts …
    assert rig.backend.gripper_opening("left") == pytest.approx(0.6, abs=2.0 / 255 + 1e-9)
    wait_for(lambda: rig.backend.gripper_opening("left") == pytest.approx(0.6))  # … and the fingers end exactly there
    assert rig.status()[4] == 102


def test_position_request_before_activation_is_ignored(rig: Rig) -> None:
    start = rig.backend.gripper_opening("left")
    rig.command(0x08, position=0)  # rGTO without rACT
    time.sleep(0.15)
    st = rig.status()
    assert rig.backend.gripper_opening("left") == start
    assert st[0] & 0x38 == 0 and st[2] == 0x07  # gGTO 0, gSTA 0, fault "activation bit must be set"
    rig.activate()  # a rising edge of rACT clears it; the request held in the registers stays idle (rGTO 0)
    assert rig.status()[2] == 0 and rig.backend.gripper_opening("left") == start


def test_request_during_activation_is_delayed() -> None:
    with make_rig(activation_time=0.5) as r:
        r.command(0)
        r.command(0x09, position=0)  # activate and go at once
        assert r.status()[2] == 0x05  # action delayed
        assert r.backend.gripper_opening("left") == 0.0
        wait_for(lambda: r.backend.gripper_opening("left") == 1.0)
        assert r.status()[2] == 0


def test_object_detected_when_fingers_stop_short() -> None:
    class Blocked(KinematicBackend):
        """An object 40 % wide between the fingers."""

        def gripper_opening(self, side: str) -> float:
            return max(0.4, super().gripper_opening(side))

    with make_rig(Blocked(grip_speed=5.0, q0=None), activation_time=0.02) as r:
        r.activate()
        r.command(0x09, position=0)
        wait_for(lambda: r.status()[0] >> 6 == 3)
        r.command(0x09, position=255, force=200)
        wait_for(lambda: r.status()[0] >> 6 == 2)  # stopped on an object while closing
        st = r.status()
        assert st[4] == round(0.6 * 255) and st[5] == 50  # gCU: holding current


def test_closed_count_sets_the_stroke() -> None:
    with make_rig(activation_time=0.02, closed_count=230) as r:
        r.activate()
        r.command(0x09, position=255)  # past the fingers touching: clamped
        wait_for(lambda: r.status()[0] >> 6 == 3)
        assert r.status()[4] == 230 and r.backend.gripper_opening("left") == 0.0


def test_reset_stops_the_fingers() -> None:
    with make_rig(KinematicBackend(grip_speed=0.5), activation_time=0.02) as rig:
        _reset_stops(rig)


def _reset_stops(rig: Rig) -> None:
    rig.activate()
    rig.command(0x09, position=0)
    time.sleep(0.05)
    rig.command(0x00)
    time.sleep(0.1)
    held = rig.backend.gripper_opening("left")
    assert 0.0 < held < 1.0
    time.sleep(0.1)
    assert rig.backend.gripper_opening("left") == held
    assert rig.status()[0] == 0


def test_exceptions_and_silence(rig: Rig) -> None:
    reply = rig.ask(modbus.read_request(9, 1000, 3), 5)  # command registers are not readable
    assert reply == modbus.exception_reply(9, 3, modbus.ILLEGAL_ADDRESS)
    reply = rig.ask(modbus.write_request(9, 2000, [0]), 5)
    assert reply == modbus.exception_reply(9, 0x10, modbus.ILLEGAL_ADDRESS)
    reply = rig.ask(modbus.read_request(9, 2001, 3), 5)  # runs past the status block
    assert reply == modbus.exception_reply(9, 3, modbus.ILLEGAL_ADDRESS)
    reply = rig.ask(modbus.with_crc(h("09 2B 0E 01 00")), 5)  # unsupported function
    assert reply == modbus.exception_reply(9, 0x2B, modbus.ILLEGAL_FUNCTION)
    bad = bytearray(modbus.read_request(9, 2000, 3))
    bad[-1] ^= 0xFF
    assert rig.silent(bytes(bad))  # bad CRC: no reply
    assert rig.silent(modbus.read_request(8, 2000, 3))  # another slave: no reply
    assert rig.status()[0] == 0  # still in step afterwards


def test_broadcast_write_is_applied_silently(rig: Rig) -> None:
    assert rig.silent(modbus.write_request(0, 1000, [0x0100, 0, 0]))
    assert rig.fake.command[0] == 0x01


def test_partial_register_write(rig: Rig) -> None:
    rig.activate()
    rig.command(0x09, position=0)
    reply = rig.ask(modbus.write_request(9, 1001, [0x0080, 0xFFFF]), 8)  # rPR 128 only, like pyRobotiqGripper
    assert reply == modbus.write_reply(9, 1001, 2)
    wait_for(lambda: rig.status()[4] == 128)


@pytest.mark.parametrize("kind", ["drop", "stall"])
def test_no_reply_faults(rig: Rig, kind: str) -> None:
    rig.fake.faults.inject(kind)
    assert rig.silent(modbus.read_request(9, 2000, 3))
    rig.fake.faults.clear(kind)
    assert len(rig.status()) == 6


def test_corrupt_fault_breaks_the_crc(rig: Rig) -> None:
    rig.fake.faults.inject("corrupt")
    reply = rig.ask(modbus.read_request(9, 2000, 3), 11)
    assert len(reply) == 11 and not modbus.crc_ok(reply)


def test_disconnect_fault_hangs_up(rig: Rig) -> None:
    rig.fake.faults.inject("disconnect")
    time.sleep(0.05)
    with pytest.raises(serial.SerialException):
        rig.port.write(modbus.read_request(9, 2000, 3))
        rig.port.read(11)


def test_a_major_fault_stops_the_fingers_where_they_are() -> None:
    # Slow fingers (2 s for the full travel), so a test thread a loaded machine lets sleep late still
    # catches them moving; the fault must stop them far short of the request, and keep them there.
    with make_rig(KinematicBackend(grip_speed=0.5)) as rig:
        rig.activate()
        rig.command(0x09, position=0)  # open fully
        wait_for(lambda: rig.backend.gripper_opening("left") > 0.05)
        rig.fake.set_fault(0x0A, persistent=True)  # under-voltage: fingers stop, activation cannot clear it
        held = rig.backend.gripper_opening("left")
        time.sleep(0.3)  # 0.15 of travel, had they gone on
        assert rig.backend.gripper_opening("left") == pytest.approx(held, abs=0.02)
        assert held < 0.6
        assert rig.status()[2] == 0x0A


def test_device_faults(rig: Rig) -> None:
    rig.activate()
    rig.command(0x09, position=0)
    rig.fake.set_fault(0x0A, persistent=True)  # under-voltage: activation cannot clear it
    assert rig.status()[2] == 0x0A
    rig.command(0)
    rig.command(0x01)
    time.sleep(0.1)
    st = rig.status()
    assert st[2] == 0x0A and st[0] >> 4 & 3 == 1  # stuck activating
    rig.fake.clear_fault()
    wait_for(lambda: rig.status()[0] >> 4 & 3 == 3)
    rig.fake.set_fault(0x0E, kflt=0x1)  # overcurrent, cleared by the next activation
    assert rig.status()[2] == 0x1E
    rig.activate()
    assert rig.status()[2] == 0
    with pytest.raises(ValueError):
        rig.fake.set_fault(0x10)


def test_automatic_release(rig: Rig) -> None:
    rig.activate()
    rig.command(0x19, position=255)  # rATR: open regardless of the request
    wait_for(lambda: rig.status()[2] == 0x0F)  # 0x0B in progress → 0x0F completed
    # Completed means open to within a quarter count; the status may be read a tick before 1.0 exactly.
    assert rig.backend.gripper_opening("left") >= RELEASED_OPENING
    wait_for(lambda: rig.backend.gripper_opening("left") == 1.0)  # and the fingers do end fully open


def test_slow_fingers_are_moving_not_blocked() -> None:
    # 0.04 /s moves less than 1e-4 per 1 ms tick: motion must be judged over the settle window.
    with make_rig(KinematicBackend(grip_speed=0.04), activation_time=0.02, tick=0.001) as r:
        r.activate()
        r.command(0x09, position=128)
        t0 = time.monotonic()
        while time.monotonic() - t0 < 0.4:
            assert r.status()[0] >> 6 == 0  # moving, no object
            time.sleep(0.02)
