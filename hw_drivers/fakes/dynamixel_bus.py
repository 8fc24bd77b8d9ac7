"""A fake Dynamixel bus on a pseudo-terminal: XM430-W350 servos speaking protocol 2.0 to the real SDK.

The driver opens :attr:`FakeDynamixelBus.path` like ``/dev/ttyUSB0``; ``dynamixel_sdk`` talks to it byte
for byte as to a U2D2 with servos behind it. What the fake implements, after the ROBOTIS e-manual and
``dynamixel_sdk/protocol2_packet_handler.py``:

* framing ``FF FF FD 00 | ID | LEN_L LEN_H | INST | PARAMS | CRC_L CRC_H``, CRC-16 (poly 0x8005, the SDK's
  table), byte stuffing (``FF FF FD`` → ``FF FF FD FD``) both ways;
* PING, READ, WRITE, REG_WRITE + ACTION, SYNC_READ, SYNC_WRITE, REBOOT; status packets (``0x55``) with the
  error byte: the alert bit (0x80) while ``Hardware_Error_Status`` is non-zero, 1 result fail, 2 instruction,
  3 CRC, 4 data range, 6 data limit, 7 access (read-only field, or EEPROM written while torque is on);
* ``Status_Return_Level`` (0 ping only, 1 ping+read, 2 all) and no reply to broadcasts except PING.

Each servo drives one gripper side of the :class:`RigBackend` through a fixed linear map of the fake:
``ticks_closed`` (default 2048) ↔ opening 0, ``ticks_open`` (default 3072, a quarter turn on) ↔ opening 1.
Goal_Position, with torque on in a position mode (3, 4, 5), becomes ``set_gripper_target``; turning torque
on tracks the *stored* goal at once (so a stale goal makes the fingers jump, as on the real servo); torque
off freezes the fingers where they are. Present_Position comes from ``gripper_opening``. Present_Current is at the
Goal_Current cap (mode 5; Current_Limit otherwise) with the sign of the position error when the fingers
have not moved for 50 ms while more than 20 ticks short of the goal (grasping), a quarter of it while
moving, 0 at the goal.

Faults (``faults.inject``): ``drop`` — a request is ignored (no effect, no status packet: the SDK reports
COMM_RX_TIMEOUT); ``corrupt`` — requests are served but every status packet goes out with a broken CRC
(COMM_RX_CORRUPT); ``stall`` — nothing is read or answered while it lasts; ``disconnect`` — the pty is
hung up for good. :meth:`FakeDynamixelBus.set_hardware_error` raises a servo hardware error (overload by
default): torque goes off (the servo's default Shutdown policy) and the alert bit is set until REBOOT.
"""

from __future__ import annotations

import contextlib
import threading
import time
from collections import Counter
from dataclasses import dataclass

from hw_drivers.fakes.backend import RigBackend, check_side
from hw_drivers.fakes.faults import FaultSwitch
from hw_drivers.fakes.pty import PtyPair

# ------------------------------------------------------------------------------------------------ codec

HEADER = b"\xff\xff\xfd\x00"
BROADCAST_ID = 0xFE
MAX_PACKET = 1024  # the SDK's RXPACKET_MAX_LEN; longer "packets" are noise

INST_PING, INST_READ, INST_WRITE, INST_REG_WRITE, INST_ACTION = 0x01, 0x02, 0x03, 0x04, 0x05
INST_REBOOT, INST_STATUS, INST_SYNC_READ, INST_SYNC_WRITE = 0x08, 0x55, 0x82, 0x83

ERR_RESULT_FAIL, ERR_INSTRUCTION, ERR_CRC, ERR_DATA_RANGE = 1, 2, 3, 4
ERR_DATA_LENGTH, ERR_DATA_LIMIT, ERR_ACCESS, ERR_ALERT = 5, 6, 7, 0x80

# Hardware_Error_Status bits (e-manual, XM430-W350 address 70)
HW_INPUT_VOLTAGE, HW_OVERHEATING, HW_ENCODER, HW_ELECTRICAL_SHOCK, HW_OVERLOAD = 0x01, 0x04, 0x08, 0x10, 0x20


def _crc_table() -> tuple[int, ...]:
    # The SDK's 256-entry table is exactly this MSB-first CRC-16 of poly 0x8005 (the test checks it).
    table = []
    for i in range(256):
        c = i << 8
        for _ in range(8):
            c = ((c << 1) ^ 0x8005) if c & 0x8000 else (c << 1)
        table.append(c & 0xFFFF)
    return tuple(table)


_CRC_TABLE = _crc_table()


def crc16(data: bytes | bytearray) -> int:
    """CRC-16 of protocol 2.0 (poly 0x8005, init 0, no reflection) over ``data``."""
    crc = 0
    for b in data:
        crc = ((crc << 8) ^ _CRC_TABLE[((crc >> 8) ^ b) & 0xFF]) & 0xFFFF
    return crc


def stuff(payload: bytes) -> bytes:
    """Insert ``FD`` after every ``FF FF FD`` of the instruction+parameters, so no header appears inside."""
    out = bytearray()
    for i, b in enumerate(payload):
        out.append(b)
        if b == 0xFD and i >= 2 and payload[i - 2] == 0xFF and payload[i - 1] == 0xFF:
            out.append(0xFD)
    return bytes(out)


def unstuff(payload: bytes) -> bytes:
    """Inverse of :func:`stuff`: ``FF FF FD FD`` → ``FF FF FD``."""
    out = bytearray()
    i = 0
    while i < len(payload):
        out.append(payload[i])
        if out[-3:] == b"\xff\xff\xfd" and i + 1 < len(payload) and payload[i + 1] == 0xFD:
            i += 1  # the stuffed byte
        i += 1
    return bytes(out)


def encode_packet(servo_id: int, payload: bytes) -> bytes:
    """A whole packet: ``payload`` is INST + PARAMS (a status packet: ``0x55, error, params``)."""
    body = stuff(payload)
    head = HEADER + bytes([servo_id]) + (len(body) + 2).to_bytes(2, "little") + body
    return head + crc16(head).to_bytes(2, "little")


def status_packet(servo_id: int, error: int, params: bytes = b"") -> bytes:
    return encode_packet(servo_id, bytes([INST_STATUS, error]) + params)


@dataclass(frozen=True)
class Packet:
    servo_id: int
    instruction: int
    params: bytes
    crc_ok: bool


def take_packets(buf: bytearray) -> list[Packet]:
    """Cut every whole packet off the front of ``buf`` (resynchronising on noise); keeps a partial tail."""
    found: list[Packet] = []
    while True:
        start = buf.find(HEADER)
        if start < 0:
            del buf[: max(0, len(buf) - 3)]  # keep a possible header prefix
            return found
        del buf[:start]
        if len(buf) < 7:
            return found
        length = int.from_bytes(buf[5:7], "little")
        if length < 3 or length > MAX_PACKET:
            del buf[:1]
            continue
        if len(buf) < 7 + length:
            return found
        raw = bytes(buf[: 7 + length])
        del buf[: 7 + length]
        payload = unstuff(raw[7:-2])
        ok = crc16(raw[:-2]) == int.from_bytes(raw[-2:], "little")
        found.append(Packet(raw[4], payload[0], payload[1:], ok))


# ------------------------------------------------------------------------------------------ control table


@dataclass(frozen=True)
class Field:
    name: str
    address: int
    size: int
    writable: bool
    default: int
    signed: bool = False


EEPROM_END = 64  # addresses below are EEPROM: writable only while torque is off
FIELDS = (
    Field("Model_Number", 0, 2, False, 1020),
    Field("Model_Information", 2, 4, False, 0),
    Field("Firmware_Version", 6, 1, False, 48),
    Field("ID", 7, 1, True, 1),
    Field("Baud_Rate", 8, 1, True, 1),
    Field("Return_Delay_Time", 9, 1, True, 0),
    Field("Drive_Mode", 10, 1, True, 0),
    Field("Operating_Mode", 11, 1, True, 3),
    Field("Secondary_ID", 12, 1, True, 255),
    Field("Protocol_Type", 13, 1, True, 2),
    Field("Homing_Offset", 20, 4, True, 0, signed=True),
    Field("Moving_Threshold", 24, 4, True, 10),
    Field("Temperature_Limit", 31, 1, True, 80),
    Field("Max_Voltage_Limit", 32, 2, True, 160),
    Field("Min_Voltage_Limit", 34, 2, True, 95),
    Field("PWM_Limit", 36, 2, True, 885),
    Field("Current_Limit", 38, 2, True, 1193),
    Field("Velocity_Limit", 44, 4, True, 200),
    Field("Max_Position_Limit", 48, 4, True, 4095),
    Field("Min_Position_Limit", 52, 4, True, 0),
    Field("Startup_Configuration", 60, 1, True, 0),
    Field("Shutdown", 63, 1, True, 52),
    Field("Torque_Enable", 64, 1, True, 0),
    Field("LED", 65, 1, True, 0),
    Field("Status_Return_Level", 68, 1, True, 2),
    Field("Registered_Instruction", 69, 1, False, 0),
    Field("Hardware_Error_Status", 70, 1, False, 0),
    Field("Velocity_I_Gain", 76, 2, True, 1920),
    Field("Velocity_P_Gain", 78, 2, True, 100),
    Field("Position_D_Gain", 80, 2, True, 0),
    Field("Position_I_Gain", 82, 2, True, 0),
    Field("Position_P_Gain", 84, 2, True, 800),
    Field("Bus_Watchdog", 98, 1, True, 0),
    Field("Goal_PWM", 100, 2, True, 885, signed=True),
    Field("Goal_Current", 102, 2, True, 1193, signed=True),
    Field("Goal_Velocity", 104, 4, True, 0, signed=True),
    Field("Profile_Acceleration", 108, 4, True, 0),
    Field("Profile_Velocity", 112, 4, True, 0),
    Field("Goal_Position", 116, 4, True, 0, signed=True),
    Field("Realtime_Tick", 120, 2, False, 0),
    Field("Moving", 122, 1, False, 0),
    Field("Moving_Status", 123, 1, False, 0),
    Field("Present_PWM", 124, 2, False, 0, signed=True),
    Field("Present_Current", 126, 2, False, 0, signed=True),
    Field("Present_Velocity", 128, 4, False, 0, signed=True),
    Field("Present_Position", 132, 4, False, 0, signed=True),
    Field("Velocity_Trajectory", 136, 4, False, 0, signed=True),
    Field("Position_Trajectory", 140, 4, False, 0, signed=True),
    Field("Present_Input_Voltage", 144, 2, False, 120),
    Field("Present_Temperature", 146, 1, False, 30),
)
BY_NAME = {f.name: f for f in FIELDS}
BY_ADDRESS = {f.address: f for f in FIELDS}
TABLE_SIZE = FIELDS[-1].address + FIELDS[-1].size
OPERATING_MODES = (0, 1, 3, 4, 5, 16)  # current, velocity, position, extended position, current-based position, PWM
POSITION_MODES = (3, 4, 5)
GRASP_TOLERANCE = 20  # ticks short of the goal that count as "stopped on something"
STILL_TICKS, STILL_TIME = 2, 0.05  # no more motion than this for this long = the fingers are not moving
VELOCITY_UNIT = 0.229 * 4096 / 60  # ticks/s per Present_Velocity unit (0.229 rpm)


class _Servo:
    """One servo's memory and the little dynamics the fake derives from the backend."""

    def __init__(self, servo_id: int, side: str, model: int) -> None:
        self.id, self.side = servo_id, side
        self.mem = bytearray(TABLE_SIZE)
        for f in FIELDS:
            self.put(f.name, f.default)
        self.put("Model_Number", model)
        self.put("ID", servo_id)
        self.registered: tuple[int, bytes] | None = None
        self.still_since, self.still_ticks = -1.0, 0  # when the fingers last moved, and where
        self.vel_t, self.vel_ticks = 0.0, 0

    def get(self, name: str) -> int:
        f = BY_NAME[name]
        return int.from_bytes(self.mem[f.address : f.address + f.size], "little", signed=f.signed)

    def put(self, name: str, value: int) -> None:
        f = BY_NAME[name]
        mask = (1 << (8 * f.size)) - 1
        self.mem[f.address : f.address + f.size] = (int(value) & mask).to_bytes(f.size, "little")

    def status_error(self, error: int = 0) -> int:
        return error | (ERR_ALERT if self.get("Hardware_Error_Status") else 0)


def _fields_in(address: int, length: int) -> list[Field] | None:
    """The fields a write of ``length`` bytes at ``address`` covers, or None if it splits one."""
    covered: list[Field] = []
    end = address + length
    for f in FIELDS:
        if f.address < end and f.address + f.size > address:
            if f.address < address or f.address + f.size > end:
                return None
            covered.append(f)
    return covered if covered and covered[0].address == address else None


# -------------------------------------------------------------------------------------------------- bus


class FakeDynamixelBus:
    """XM430-W350 servos (``servos``: id → gripper side) on one pseudo-terminal; see the module docstring."""

    def __init__(
        self,
        backend: RigBackend,
        servos: dict[int, str],
        faults: FaultSwitch | None = None,
        model: int = 1020,
        *,
        ticks_closed: int = 2048,
        ticks_open: int = 3072,
    ) -> None:
        if not servos:
            raise ValueError("servos: expected at least one id → side")
        for sid, side in servos.items():
            check_side(side)
            if not 0 <= sid <= 252:
                raise ValueError(f"servos: id {sid} outside 0 … 252")
        if ticks_open == ticks_closed:
            raise ValueError("ticks_open must differ from ticks_closed")
        self._backend = backend
        self.faults = faults if faults is not None else FaultSwitch()
        self._ticks_closed, self._ticks_open = ticks_closed, ticks_open
        self._servos = {sid: _Servo(sid, side, model) for sid, side in sorted(servos.items())}
        self._pty = PtyPair()
        self.path = self._pty.path
        self._lock = threading.RLock()
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        self._log: list[tuple[int, str, int]] = []
        self.instructions: Counter[int] = Counter()  # instruction code → packets served (for tests)
        self.hung_up = False

    # -- mapping between the fake's ticks and the backend's opening

    def opening_of(self, ticks: int) -> float:
        return min(1.0, max(0.0, (ticks - self._ticks_closed) / (self._ticks_open - self._ticks_closed)))

    def ticks_of(self, opening: float) -> int:
        return round(self._ticks_closed + opening * (self._ticks_open - self._ticks_closed))

    # -- lifecycle

    def start(self) -> FakeDynamixelBus:
        if self._thread is None:
            with self._lock:
                for servo in self._servos.values():  # power-on: the goal is where the servo stands
                    self._refresh(servo)
                    servo.put("Goal_Position", servo.get("Present_Position"))
            self._thread = threading.Thread(target=self._serve, name="fake-dynamixel", daemon=True)
            self._thread.start()
        return self

    def stop(self) -> None:
        self._stop.set()
        if self._thread is not None:
            self._thread.join(2.0)
        self._pty.close()

    def __enter__(self) -> FakeDynamixelBus:
        return self.start()

    def __exit__(self, *exc: object) -> None:
        self.stop()

    # -- test back doors (bypass the protocol's access rules)

    def register(self, servo_id: int, name: str) -> int:
        with self._lock:
            servo = self._servos[servo_id]
            self._refresh(servo)
            return servo.get(name)

    def set_register(self, servo_id: int, name: str, value: int) -> None:
        """Poke a value as a previous session would have left it (e.g. a stale Goal_Position)."""
        with self._lock:
            self._servos[servo_id].put(name, value)

    def set_hardware_error(self, servo_id: int, bits: int = HW_OVERLOAD) -> None:
        """Raise a hardware error: torque off, alert bit in every status packet until REBOOT."""
        with self._lock:
            servo = self._servos[servo_id]
            servo.put("Hardware_Error_Status", bits)
            if bits:
                self._set_torque(servo, 0)

    def writes(self, servo_id: int) -> list[tuple[str, int]]:
        """Every field written to ``servo_id`` over the protocol, in order: (name, value)."""
        with self._lock:
            return [(name, v) for sid, name, v in self._log if sid == servo_id]

    # -- serving

    def _serve(self) -> None:
        buf = bytearray()
        while not self._stop.is_set():
            if self.faults.active("disconnect"):
                self.hung_up = True
                self._pty.close()
                return
            data = self._pty.read(4096, timeout=0.005)
            if not data or self.faults.active("stall"):
                continue
            buf += data
            for packet in take_packets(buf):
                if self.faults.active("drop"):
                    continue
                with self._lock:
                    replies = self._handle(packet)
                if replies and self.faults.active("corrupt"):
                    replies = [r[:-1] + bytes([r[-1] ^ 0x5A]) for r in replies]
                with contextlib.suppress(OSError):
                    self._pty.write(b"".join(replies))

    def _targets(self, servo_id: int) -> list[_Servo]:
        if servo_id == BROADCAST_ID:
            return list(self._servos.values())
        servo = self._servos.get(servo_id)
        return [servo] if servo is not None else []

    def _handle(self, p: Packet) -> list[bytes]:
        self.instructions[p.instruction] += 1
        if p.instruction == INST_SYNC_READ:
            return self._sync_read(p) if p.crc_ok else []
        if p.instruction == INST_SYNC_WRITE:
            if p.crc_ok:
                self._sync_write(p)
            return []
        replies = []
        for servo in self._targets(p.servo_id):
            error, params = self._instruction(servo, p) if p.crc_ok else (ERR_CRC, b"")
            level = servo.get("Status_Return_Level")
            wants = p.instruction == INST_PING or (level >= 1 and p.instruction == INST_READ) or level >= 2
            if p.instruction == INST_PING or (p.servo_id != BROADCAST_ID and p.instruction != INST_ACTION and wants):
                replies.append(status_packet(servo.id, servo.status_error(error), params))
            if p.instruction == INST_REBOOT and error == 0:
                self._reboot(servo)  # after the reply, like the real servo
        return replies

    def _instruction(self, servo: _Servo, p: Packet) -> tuple[int, bytes]:
        inst, params = p.instruction, p.params
        if inst == INST_PING:
            return 0, bytes(servo.mem[0:2] + servo.mem[6:7])
        if inst == INST_READ:
            if len(params) != 4:
                return ERR_DATA_LENGTH, b""
            address, length = int.from_bytes(params[0:2], "little"), int.from_bytes(params[2:4], "little")
            return self._read(servo, address, length)
        if inst in (INST_WRITE, INST_REG_WRITE):
            if len(params) < 3:
                return ERR_DATA_LENGTH, b""
            address, data = int.from_bytes(params[0:2], "little"), bytes(params[2:])
            if inst == INST_REG_WRITE:
                servo.registered = (address, data)
                servo.put("Registered_Instruction", 1)
                return 0, b""
            return self._write(servo, address, data), b""
        if inst == INST_ACTION:
            if servo.registered is None:
                return ERR_RESULT_FAIL, b""
            address, data = servo.registered
            servo.registered = None
            servo.put("Registered_Instruction", 0)
            return self._write(servo, address, data), b""
        if inst == INST_REBOOT:
            return 0, b""
        return ERR_INSTRUCTION, b""

    def _sync_read(self, p: Packet) -> list[bytes]:
        if len(p.params) < 5:
            return []
        address, length = int.from_bytes(p.params[0:2], "little"), int.from_bytes(p.params[2:4], "little")
        replies = []
        for sid in p.params[4:]:  # each listed servo answers in the order asked
            servo = self._servos.get(sid)
            if servo is not None:
                error, data = self._read(servo, address, length)
                replies.append(status_packet(sid, servo.status_error(error), data))
        return replies

    def _sync_write(self, p: Packet) -> None:
        if len(p.params) < 5:
            return
        address, length = int.from_bytes(p.params[0:2], "little"), int.from_bytes(p.params[2:4], "little")
        body = p.params[4:]
        for i in range(0, len(body) - length, length + 1):
            servo = self._servos.get(body[i])
            if servo is not None:
                self._write(servo, address, bytes(body[i + 1 : i + 1 + length]))

    # -- the servo's behaviour

    def _read(self, servo: _Servo, address: int, length: int) -> tuple[int, bytes]:
        if length == 0 or address + length > TABLE_SIZE:
            return ERR_ACCESS, b""
        self._refresh(servo)
        return 0, bytes(servo.mem[address : address + length])

    def _write(self, servo: _Servo, address: int, data: bytes) -> int:
        fields = _fields_in(address, len(data))
        if fields is None or not all(f.writable for f in fields):
            return ERR_ACCESS
        if servo.get("Torque_Enable") and any(f.address < EEPROM_END for f in fields):
            return ERR_ACCESS  # EEPROM is locked while torque is on
        values = {
            f.name: int.from_bytes(data[f.address - address : f.address - address + f.size], "little", signed=f.signed)
            for f in fields
        }
        error = self._check_values(servo, values)
        if error:
            return error
        torque_before = servo.get("Torque_Enable")
        servo.mem[address : address + len(data)] = data
        self._log.extend((servo.id, name, v) for name, v in values.items())
        if "Torque_Enable" in values:
            servo.put("Torque_Enable", torque_before)  # _set_torque applies the change with its effects
            self._set_torque(servo, values["Torque_Enable"])
        elif "Goal_Position" in values and servo.get("Torque_Enable"):
            self._track_goal(servo)
        return 0

    def _check_values(self, servo: _Servo, values: dict[str, int]) -> int:
        mode = values.get("Operating_Mode", servo.get("Operating_Mode"))
        if mode not in OPERATING_MODES or values.get("Torque_Enable", 0) not in (0, 1):
            return ERR_DATA_RANGE
        if "Goal_Current" in values and abs(values["Goal_Current"]) > servo.get("Current_Limit"):
            return ERR_DATA_LIMIT
        low, high = servo.get("Min_Position_Limit"), servo.get("Max_Position_Limit")
        # the position limits bind in position mode (3) only; modes 4 and 5 are multi-turn
        if "Goal_Position" in values and mode == 3 and not low <= values["Goal_Position"] <= high:
            return ERR_DATA_LIMIT
        return 0

    def _set_torque(self, servo: _Servo, on: int) -> None:
        if on and servo.get("Hardware_Error_Status"):
            on = 0  # a servo in hardware error keeps its torque off until rebooted
        servo.put("Torque_Enable", on)
        if on:
            self._track_goal(servo)  # the stored goal, stale or not: the real servo jumps to it
        else:
            self._backend.set_gripper_target(servo.side, self._backend.gripper_opening(servo.side))

    def _track_goal(self, servo: _Servo) -> None:
        if servo.get("Operating_Mode") in POSITION_MODES:
            self._backend.set_gripper_target(servo.side, self.opening_of(servo.get("Goal_Position")))
            servo.still_since = time.monotonic()  # starting to move: not "stopped on something" yet

    def _reboot(self, servo: _Servo) -> None:
        for f in FIELDS:
            if f.address >= EEPROM_END:
                servo.put(f.name, f.default)
        servo.registered = None
        self._set_torque(servo, 0)
        self._refresh(servo)
        servo.put("Goal_Position", servo.get("Present_Position"))

    def _refresh(self, servo: _Servo) -> None:
        """Present_* from the backend, computed when read (like the servo's own sampling, but lazily)."""
        now = time.monotonic()
        ticks = self.ticks_of(self._backend.gripper_opening(servo.side))
        if abs(ticks - servo.still_ticks) > STILL_TICKS:
            servo.still_since, servo.still_ticks = now, ticks
        if now - servo.vel_t >= 0.02:
            velocity = (ticks - servo.vel_ticks) / (now - servo.vel_t) if servo.vel_t else 0.0
            servo.put("Present_Velocity", round(velocity / VELOCITY_UNIT))
            servo.vel_t, servo.vel_ticks = now, ticks
        moving = now - servo.still_since < STILL_TIME
        current = 0
        if servo.get("Torque_Enable") and servo.get("Operating_Mode") in POSITION_MODES:
            error = servo.get("Goal_Position") - ticks
            cap = servo.get("Goal_Current") if servo.get("Operating_Mode") == 5 else servo.get("Current_Limit")
            sign = 1 if error > 0 else -1
            if abs(error) > GRASP_TOLERANCE:
                current = sign * (abs(cap) // 4 if moving else abs(cap))
        servo.put("Present_Position", ticks)
        servo.put("Present_Current", current)
        servo.put("Moving", int(moving))
        servo.put("Realtime_Tick", int(now * 1000) % 32768)
