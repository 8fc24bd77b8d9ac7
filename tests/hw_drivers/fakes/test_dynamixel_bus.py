"""The fake Dynamixel bus against the real ``dynamixel_sdk`` and against hand-built packets.

Hand-built packets come from the ROBOTIS e-manual (protocol 2.0 examples), so the codec is checked
against the documented wire format and not only against itself or the SDK.
"""

from __future__ import annotations

import os
import random
import select
import time
from collections.abc import Iterator
from typing import Any

import numpy as np
import pytest
from dynamixel_sdk import (
    COMM_RX_CORRUPT,
    COMM_RX_TIMEOUT,
    COMM_SUCCESS,
    GroupSyncRead,
    GroupSyncWrite,
    PacketHandler,
    PortHandler,
)

from hw_drivers.fakes.backend import KinematicBackend
from hw_drivers.fakes.dynamixel_bus import (
    HW_OVERLOAD,
    INST_SYNC_WRITE,
    FakeDynamixelBus,
    crc16,
    encode_packet,
    status_packet,
    stuff,
    take_packets,
    unstuff,
)
from hw_drivers.fakes.faults import FaultSwitch
from pilworld.types import LEFT_GRIP, STATE_DIM

# e-manual, protocol 2.0: "Ping" and "Read" examples (ID 1)
PING_1 = bytes.fromhex("FF FF FD 00 01 03 00 01 19 4E")
PING_1_STATUS_XM430_W210 = bytes.fromhex("FF FF FD 00 01 07 00 55 00 06 04 26 65 5D")  # model 1030, fw 38
READ_POSITION_1 = bytes.fromhex("FF FF FD 00 01 07 00 02 84 00 04 00 1D 15")  # read 4 bytes at 132
MARGIN_MS = 250.0


class PatientPort(PortHandler):  # type: ignore[misc]
    """The SDK's port waiting MARGIN_MS longer for a status packet than its ~34 ms, without spinning.

    The fake answers in well under a millisecond, but on a loaded CI machine its thread may not be
    scheduled within the SDK's 34 ms; a missed deadline here would be a test flake, not a finding. The
    stock port polls a non-blocking read in a tight loop, which in one process starves the fake's thread
    of the GIL; a 1 ms read timeout (as in the driver's port) lets it sleep instead.
    """

    def setupPort(self, cflag_baud: int) -> bool:  # noqa: N802 (the SDK's name)
        ok = bool(super().setupPort(cflag_baud))
        self.ser.timeout = 0.001
        return ok

    def setPacketTimeout(self, packet_length: int) -> None:  # noqa: N802 (the SDK's name)
        super().setPacketTimeout(packet_length)
        self.packet_timeout += MARGIN_MS


def _open(path: str) -> Any:
    port = PatientPort(path)
    assert port.setBaudRate(57600)
    return port


class Rig:
    def __init__(self, bus: FakeDynamixelBus, backend: KinematicBackend, faults: FaultSwitch) -> None:
        self.bus, self.backend, self.faults = bus, backend, faults
        self.port = _open(bus.path)
        self.ph: Any = PacketHandler(2.0)


@pytest.fixture
def rig() -> Iterator[Rig]:
    q0 = np.zeros(STATE_DIM)
    q0[LEFT_GRIP] = 0.5
    backend = KinematicBackend(q0=q0, grip_speed=5.0)
    faults = FaultSwitch()
    with FakeDynamixelBus(backend, {1: "left", 2: "right"}, faults) as bus:
        r = Rig(bus, backend, faults)
        yield r
        if not bus.hung_up:
            r.port.closePort()


def _raw_exchange(path: str, packet: bytes, wait: float = 0.5) -> bytes:
    """Write raw bytes to the bus and collect the reply (no SDK involved)."""
    fd = os.open(path, os.O_RDWR | os.O_NOCTTY)
    try:
        os.write(fd, packet)
        out = b""
        deadline = time.monotonic() + wait
        while time.monotonic() < deadline:
            ready, _, _ = select.select([fd], [], [], 0.02)
            if ready:
                out += os.read(fd, 1024)
            elif out:
                break
        return out
    finally:
        os.close(fd)


# ------------------------------------------------------------------------------------------------ codec


def test_crc_matches_the_sdk_table() -> None:
    ph: Any = PacketHandler(2.0)
    rng = random.Random(1)
    for n in (1, 2, 7, 40, 300):
        data = bytes(rng.randrange(256) for _ in range(n))
        assert crc16(data) == ph.updateCRC(0, list(data), n)


def test_codec_reproduces_the_emanual_packets() -> None:
    assert encode_packet(1, b"\x01") == PING_1
    assert encode_packet(1, b"\x02\x84\x00\x04\x00") == READ_POSITION_1
    assert status_packet(1, 0, b"\x06\x04\x26") == PING_1_STATUS_XM430_W210


def test_stuffing_both_ways_and_as_the_sdk_does_it() -> None:
    payload = b"\x03\x14\x00\xff\xff\xfd\x00\xff\xff\xfd\xfd"
    stuffed = stuff(payload)
    assert stuffed == b"\x03\x14\x00\xff\xff\xfd\xfd\x00\xff\xff\xfd\xfd\xfd"
    assert unstuff(stuffed) == payload
    # the SDK stuffs a whole packet in place; its result must equal ours
    ph: Any = PacketHandler(2.0)
    sdk = [0xFF, 0xFF, 0xFD, 0x00, 1, *(len(payload) + 2).to_bytes(2, "little"), *payload, 0, 0]
    sdk = ph.addStuffing(sdk)
    assert bytes(sdk[7:-2]) == stuffed
    assert encode_packet(1, payload)[7:-2] == stuffed


def test_take_packets_resyncs_on_noise_and_keeps_a_partial_tail() -> None:
    buf = bytearray(b"\x00\x13" + PING_1 + READ_POSITION_1[:9])
    packets = take_packets(buf)
    assert [(p.servo_id, p.instruction, p.crc_ok) for p in packets] == [(1, 1, True)]
    buf += READ_POSITION_1[9:]
    (read,) = take_packets(buf)
    assert read.instruction == 2 and read.params == b"\x84\x00\x04\x00" and read.crc_ok
    bad = bytearray(PING_1[:-1] + b"\x00")
    assert not take_packets(bad)[0].crc_ok


def test_hand_built_packets_on_the_wire() -> None:
    with FakeDynamixelBus(KinematicBackend(), {1: "left"}, model=1030) as bus:
        bus.set_register(1, "Firmware_Version", 38)
        assert _raw_exchange(bus.path, PING_1) == PING_1_STATUS_XM430_W210
        reply = _raw_exchange(bus.path, READ_POSITION_1)
        assert reply[:9] == bytes.fromhex("FF FF FD 00 01 08 00 55 00")
        assert int.from_bytes(reply[9:13], "little") == 2048  # opening 0 = ticks_closed
        assert crc16(reply[:-2]) == int.from_bytes(reply[-2:], "little")
        # a packet with a bad CRC is answered with the CRC error
        assert _raw_exchange(bus.path, PING_1[:-1] + b"\x00") == status_packet(1, 3)


# ------------------------------------------------------------------------------------- the real SDK


def test_ping_read_write(rig: Rig) -> None:
    port, ph = rig.port, rig.ph
    assert ph.ping(port, 1) == (1020, COMM_SUCCESS, 0)
    assert ph.ping(port, 9)[1] == COMM_RX_TIMEOUT  # nobody there
    assert ph.read2ByteTxRx(port, 1, 0) == (1020, COMM_SUCCESS, 0)
    assert ph.read4ByteTxRx(port, 1, 132) == (2560, COMM_SUCCESS, 0)  # opening 0.5: 2048 + 0.5 × 1024
    assert ph.write1ByteTxRx(port, 1, 11, 5) == (COMM_SUCCESS, 0)
    assert rig.bus.register(1, "Operating_Mode") == 5
    assert ph.write2ByteTxRx(port, 1, 102, 200) == (COMM_SUCCESS, 0)
    assert ph.read2ByteTxRx(port, 1, 102) == (200, COMM_SUCCESS, 0)
    found, result = ph.broadcastPing(port)
    assert result == COMM_SUCCESS and sorted(found) == [1, 2]


def test_stuffed_values_round_trip_through_the_sdk(rig: Rig) -> None:
    value = int.from_bytes(b"\xff\xff\xfd\x00", "little")  # stuffed on the way in and on the way out
    assert rig.ph.write4ByteTxRx(rig.port, 1, 24, value) == (COMM_SUCCESS, 0)  # Moving_Threshold
    assert rig.bus.register(1, "Moving_Threshold") == value
    assert rig.ph.read4ByteTxRx(rig.port, 1, 24) == (value, COMM_SUCCESS, 0)


def test_access_rules_like_the_servo(rig: Rig) -> None:
    port, ph = rig.port, rig.ph
    assert ph.write1ByteTxRx(port, 1, 64, 1) == (COMM_SUCCESS, 0)
    assert ph.write1ByteTxRx(port, 1, 11, 5) == (COMM_SUCCESS, 7)  # EEPROM while torque is on: access error
    assert rig.bus.register(1, "Operating_Mode") == 3
    assert ph.write2ByteTxRx(port, 1, 126, 5)[1] == 7  # Present_Current is read-only
    assert ph.write1ByteTxRx(port, 1, 117, 5)[1] == 7  # half a field
    assert ph.write4ByteTxRx(port, 1, 116, 5000)[1] == 6  # beyond Max_Position_Limit: data limit
    assert ph.write2ByteTxRx(port, 1, 102, 2000)[1] == 6  # beyond Current_Limit
    assert ph.write1ByteTxRx(port, 1, 64, 0) == (COMM_SUCCESS, 0)
    assert ph.write1ByteTxRx(port, 1, 11, 7)[1] == 4  # no such mode: data range


def test_goal_drives_the_backend_only_with_torque_on(rig: Rig) -> None:
    port, ph = rig.port, rig.ph
    assert ph.write4ByteTxRx(port, 1, 116, 2048) == (COMM_SUCCESS, 0)  # torque off: stored, no motion
    time.sleep(0.1)
    assert rig.backend.gripper_opening("left") == pytest.approx(0.5)
    ph.write1ByteTxRx(port, 1, 64, 1)  # torque on tracks the stored goal at once (the stale-goal jump)
    time.sleep(0.2)
    assert rig.backend.gripper_opening("left") == pytest.approx(0.0)
    ph.write4ByteTxRx(port, 1, 116, 2816)
    time.sleep(0.3)
    assert ph.read4ByteTxRx(port, 1, 132)[0] == 2816
    assert rig.backend.gripper_opening("left") == pytest.approx(0.75)


def test_sync_read_and_sync_write(rig: Rig) -> None:
    port, ph = rig.port, rig.ph
    for sid in (1, 2):
        ph.write1ByteTxRx(port, sid, 64, 1)
    write = GroupSyncWrite(port, ph, 116, 4)
    write.addParam(1, list((2176).to_bytes(4, "little")))
    write.addParam(2, list((2944).to_bytes(4, "little")))
    assert write.txPacket() == COMM_SUCCESS
    time.sleep(0.3)
    read = GroupSyncRead(port, ph, 116, 20)
    assert read.addParam(1) and read.addParam(2)
    assert read.txRxPacket() == COMM_SUCCESS
    assert [read.getData(sid, 116, 4) for sid in (1, 2)] == [2176, 2944]
    assert [read.getData(sid, 132, 4) for sid in (1, 2)] == [2176, 2944]
    assert rig.backend.gripper_opening("left") == pytest.approx(0.125)
    assert rig.backend.gripper_opening("right") == pytest.approx(0.875)
    assert rig.bus.instructions[INST_SYNC_WRITE] == 1


def test_reg_write_action_and_reboot(rig: Rig) -> None:
    port, ph = rig.port, rig.ph
    assert ph.regWriteTxRx(port, 1, 102, 2, [100, 0]) == (COMM_SUCCESS, 0)
    assert rig.bus.register(1, "Goal_Current") == 1193
    assert ph.action(port, 1) == COMM_SUCCESS
    time.sleep(0.05)
    assert rig.bus.register(1, "Goal_Current") == 100
    ph.write1ByteTxRx(port, 1, 64, 1)
    rig.bus.set_hardware_error(1, HW_OVERLOAD)
    assert ph.read1ByteTxRx(port, 1, 70) == (HW_OVERLOAD, COMM_SUCCESS, 0x80)  # the alert bit
    assert rig.bus.register(1, "Torque_Enable") == 0  # the servo's shutdown policy
    assert ph.write1ByteTxRx(port, 1, 64, 1) == (COMM_SUCCESS, 0x80)
    assert rig.bus.register(1, "Torque_Enable") == 0  # stays off until rebooted
    assert ph.reboot(port, 1) == (COMM_SUCCESS, 0x80)  # answered before the reboot
    time.sleep(0.05)
    assert ph.read1ByteTxRx(port, 1, 70) == (0, COMM_SUCCESS, 0)
    assert ph.read2ByteTxRx(port, 1, 102) == (1193, COMM_SUCCESS, 0)  # RAM back to defaults


def test_present_current_reaches_the_cap_when_the_fingers_are_blocked() -> None:
    class Blocked(KinematicBackend):
        def gripper_opening(self, side: str) -> float:
            return max(0.4, super().gripper_opening(side))  # an object 0.4 wide between the fingers

    with FakeDynamixelBus(Blocked(grip_speed=5.0), {1: "left"}) as bus:
        port = _open(bus.path)
        ph: Any = PacketHandler(2.0)
        ph.write1ByteTxRx(port, 1, 11, 5)
        ph.write2ByteTxRx(port, 1, 102, 150)
        ph.write1ByteTxRx(port, 1, 64, 1)
        assert ph.read2ByteTxRx(port, 1, 126)[0] == 0  # at the goal: no effort
        ph.write4ByteTxRx(port, 1, 116, 2816)  # open: moves freely
        time.sleep(0.02)
        assert ph.read1ByteTxRx(port, 1, 122)[0] == 1
        time.sleep(0.3)
        assert ph.read2ByteTxRx(port, 1, 126)[0] == 0
        ph.write4ByteTxRx(port, 1, 116, 2048)  # close on the object
        deadline = time.monotonic() + 1.0
        while ph.read1ByteTxRx(port, 1, 122)[0] or ph.read4ByteTxRx(port, 1, 132)[0] > 2458:  # 0.4 → 2457.6
            assert time.monotonic() < deadline
            time.sleep(0.01)
        time.sleep(0.06)
        current = ph.read2ByteTxRx(port, 1, 126)[0]
        assert current - (1 << 16) == -150  # signed: pushing toward closed, at the cap
        port.closePort()


# ------------------------------------------------------------------------------------------------ faults


def test_drop_and_stall_give_no_status_packet(rig: Rig) -> None:
    for kind in ("drop", "stall"):
        rig.faults.inject(kind)
        assert rig.ph.ping(rig.port, 1)[1] == COMM_RX_TIMEOUT
        rig.faults.clear()
        assert rig.ph.ping(rig.port, 1)[1] == COMM_SUCCESS


def test_dropped_write_has_no_effect(rig: Rig) -> None:
    rig.faults.inject("drop")
    assert rig.ph.write2ByteTxRx(rig.port, 1, 102, 50)[0] == COMM_RX_TIMEOUT
    rig.faults.clear()
    assert rig.bus.register(1, "Goal_Current") == 1193


def test_corrupt_replies_fail_the_crc(rig: Rig) -> None:
    rig.faults.inject("corrupt")
    assert rig.ph.ping(rig.port, 1)[1] == COMM_RX_CORRUPT
    assert rig.ph.read4ByteTxRx(rig.port, 1, 132)[1] == COMM_RX_CORRUPT
    rig.faults.clear()
    assert rig.ph.read4ByteTxRx(rig.port, 1, 132)[1] == COMM_SUCCESS


def test_disconnect_hangs_up_the_pty(rig: Rig) -> None:
    rig.faults.inject("disconnect")
    deadline = time.monotonic() + 1.0
    while not rig.bus.hung_up:
        assert time.monotonic() < deadline
        time.sleep(0.005)
    with pytest.raises(Exception) as info:  # the SDK does not catch it: pyserial/termios raise
        rig.ph.ping(rig.port, 1)
    assert isinstance(info.value, OSError) or type(info.value).__name__ == "error"
