"""A gripper on one Dynamixel X servo (XM430-W350, protocol 2.0) through the real ``dynamixel_sdk``.

The servo runs in current-based position mode (Operating_Mode 5): it tracks Goal_Position but never
pushes harder than Goal_Current, so closing on an object squeezes it with a bounded force and the
current sitting at that cap tells us something is held.

Start-up never moves the fingers: torque off → mode 5 → Goal_Current → Goal_Position := Present_Position
→ torque on. (A servo keeps its last Goal_Position while powered; enabling torque on a stale goal makes the
gripper jump — the most common complaint about Dynamixel grippers.)

One background thread owns the port. Every cycle (``poll_hz``) it writes the latest target if the servo's
goal differs from it (a GroupSyncWrite; a lost write is seen in the next read-back and repeated) and reads
Goal_Position … Present_Position in one GroupSyncRead; at ~10 Hz it also reads Torque_Enable and
Hardware_Error_Status. A transaction that times out or comes back corrupted is retried ``retries`` times;
then the thread stores a typed error (``DeviceTimeoutError``, ``DeviceProtocolError``, ``DeviceFaultError``
for a servo hardware error, ``DeviceConnectionError`` when the port is gone) and stops, and the next
``set_target``/``status`` raises it. Nothing here falls back to a fake or a default.
"""

from __future__ import annotations

import logging
import math
import termios
import threading
import time
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any, TypeVar

from dynamixel_sdk import (
    COMM_RX_CORRUPT,
    COMM_RX_TIMEOUT,
    COMM_SUCCESS,
    GroupSyncRead,
    GroupSyncWrite,
    PacketHandler,
    PortHandler,
)

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
from hw_drivers.grippers.base import GripperStatus, RoundTripStats
from hw_drivers.grippers.calibration import TickMapping

log = logging.getLogger(__name__)
T = TypeVar("T")

MODEL_XM430_W350 = 1020
MODEL_NAMES = {1020: "XM430-W350", 1030: "XM430-W210", 1060: "XL430-W250", 1190: "XL330-M077", 1200: "XL330-M288"}
BAUDRATES = (9600, 57600, 115200, 1000000, 2000000, 3000000, 4000000)  # what an X-series servo can be set to
CURRENT_UNIT_MA = 2.69  # XM430-W350: one unit of Goal/Present_Current

# Control table (XM430-W350, protocol 2.0)
OPERATING_MODE, CURRENT_LIMIT = 11, 38  # EEPROM
TORQUE_ENABLE, HARDWARE_ERROR_STATUS, GOAL_CURRENT, GOAL_POSITION = 64, 70, 102, 116
MOVING, PRESENT_CURRENT, PRESENT_POSITION = 122, 126, 132
CURRENT_BASED_POSITION = 5
READ_START, READ_LENGTH = GOAL_POSITION, PRESENT_POSITION + 4 - GOAL_POSITION  # 116 … 135 in one read
HEALTH_START, HEALTH_LENGTH = TORQUE_ENABLE, HARDWARE_ERROR_STATUS + 1 - TORQUE_ENABLE  # 64 … 70
HEALTH_HZ = 10.0
ERRBIT_ALERT = 0x80
HARDWARE_ERRORS = {0x01: "input voltage", 0x04: "overheating", 0x08: "motor encoder", 0x10: "electrical shock"}
HARDWARE_ERRORS[0x20] = "overload"
CALIBRATION_SLACK = 0.1  # fraction of the travel the fingers may stand outside the calibration at start-up
GRASP_TICKS = 20  # further than this from the goal, stopped, current at the cap = holding something
GRASP_CURRENT = 0.9  # fraction of the cap that counts as "at the cap"
IO_ERRORS = (OSError, termios.error)  # pyserial's SerialException is an OSError; tcflush raises termios.error


@dataclass(frozen=True)
class _Reading:
    goal: int  # ticks, the goal the servo holds
    position: int  # ticks
    current: int  # units of CURRENT_UNIT_MA, signed
    moving: bool
    t: float  # time.monotonic() when the answer arrived


class _StopRequestedError(Exception):
    """disconnect() asked the I/O thread to stop in the middle of retrying."""


def _signed(value: int, bits: int) -> int:
    return value - (1 << bits) if value >= 1 << (bits - 1) else value


def _decode_hardware(bits: int) -> str:
    names = [name for bit, name in HARDWARE_ERRORS.items() if bits & bit]
    return ", ".join(names) or f"0x{bits:02x}"


class _Port(PortHandler):  # type: ignore[misc]
    """The SDK's port with two changes: our status-packet timeout, and short blocking reads.

    The SDK polls a non-blocking port in a tight loop while it waits for a status packet (a whole core
    per waiting bus); a 1 ms read timeout lets the thread sleep in ``select`` instead. The SDK always asks
    for exactly the bytes it still needs, so a read returns as soon as they are there.
    """

    def __init__(self, port_name: str, timeout_ms: float) -> None:
        super().__init__(port_name)
        self._timeout_ms = timeout_ms

    def setupPort(self, cflag_baud: int) -> bool:  # noqa: N802 (the SDK's name)
        ok = bool(super().setupPort(cflag_baud))
        self.ser.timeout = 0.001
        return ok

    def setPacketTimeout(self, packet_length: int) -> None:  # noqa: N802 (the SDK's name)
        # transmission time of the expected answer + our margin (the SDK's is 2 × the FTDI latency + 2 ms)
        self.setPacketTimeoutMillis(self.tx_time_per_byte * packet_length + self._timeout_ms)


class DynamixelGripper:
    """The :class:`~hw_drivers.grippers.base.Gripper` contract on one XM430-W350; see the module docstring.

    ``ticks_closed``/``ticks_open``: Present_Position with the fingers closed / fully open (either order).
    ``current_limit_ma``: the squeeze (Goal_Current). ``timeout``: seconds to wait for a status packet.
    ``retries``: extra attempts of a timed-out or corrupted transaction before the error is stored.
    """

    def __init__(
        self,
        name: str,
        port: str,
        servo_id: int,
        *,
        baudrate: int = 57600,
        ticks_closed: int,
        ticks_open: int,
        current_limit_ma: float = 300.0,
        poll_hz: float = 100.0,
        retries: int = 2,
        timeout: float = 0.04,
        model: int = MODEL_XM430_W350,
    ) -> None:
        if not 0 <= servo_id <= 252:
            raise ValueError(f"servo_id: expected 0 … 252, got {servo_id}")
        if baudrate not in BAUDRATES:
            raise ValueError(f"baudrate: expected one of {BAUDRATES}, got {baudrate}")
        if not current_limit_ma > 0 or not poll_hz > 0 or not timeout > 0 or retries < 0:
            raise ValueError("current_limit_ma, poll_hz and timeout must be > 0 and retries >= 0")
        self._name, self._port_name, self._id = name, port, servo_id
        self._baudrate, self._model = baudrate, model
        self.calibration = TickMapping(ticks_closed, ticks_open)
        self._cap = round(current_limit_ma / CURRENT_UNIT_MA)
        self._period = 1.0 / poll_hz
        self._retries, self._timeout = retries, timeout
        self._ph: Any = PacketHandler(2.0)
        self._port: Any = None
        self._sync_read: Any = None
        self._sync_write: Any = None
        self._lock = threading.Lock()
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        self._connected = False
        self._error: RobotError | None = None
        self._target: int | None = None  # ticks; written by set_target, sent by the I/O thread
        self._reading: _Reading | None = None
        self._roundtrips: deque[float] = deque(maxlen=2000)

    # -- the Gripper contract

    @property
    def name(self) -> str:
        return self._name

    @property
    def is_connected(self) -> bool:
        return self._connected and self._error is None

    def connect(self) -> None:
        if self._connected:
            raise DeviceAlreadyConnectedError(self._name, "already connected")
        self._error, self._reading = None, None
        self._stop.clear()
        port = _Port(self._port_name, self._timeout * 1000.0)
        try:
            # setBaudRate opens the port at that rate (openPort would first open it at the SDK's 1 Mbaud)
            opened = port.setBaudRate(self._baudrate)
        except IO_ERRORS as e:
            raise DeviceConnectionError(self._name, f"cannot open serial port {self._port_name}: {e}") from e
        if not opened:
            raise DeviceConnectionError(self._name, f"cannot set {self._baudrate} baud on {self._port_name}")
        self._port = port
        try:
            self._configure()
        except BaseException:
            self._close_port()
            raise
        self._connected = True
        self._thread = threading.Thread(target=self._run, name=f"dynamixel-{self._name}", daemon=True)
        self._thread.start()

    def disconnect(self) -> None:
        self._stop.set()
        thread_alive = False
        if self._thread is not None:
            self._thread.join(2.0)  # it stops between retries: at most one transaction (~timeout)
            thread_alive = self._thread.is_alive()
            if thread_alive:
                log.warning("%s: the I/O thread did not stop within 2 s", self._name)
            self._thread = None
        if self._port is not None:
            if not thread_alive:  # never two threads on one port
                self._port.is_using = False  # an exception inside the SDK leaves its port marked busy
                try:  # best effort: a gone or stalled bus must not keep disconnect() from finishing
                    self._ph.write1ByteTxRx(self._port, self._id, TORQUE_ENABLE, 0)
                except Exception as e:
                    log.warning("%s: torque off failed: %s", self._name, e)
            self._close_port()
        self._connected = False

    def set_target(self, opening: float) -> float:
        if not math.isfinite(opening):
            raise ValueError(f"opening: expected a finite number, got {opening!r}")
        clipped = min(1.0, max(0.0, float(opening)))
        with self._lock:
            self._check()
            self._target = self.calibration.to_ticks(clipped)
        return clipped

    def status(self, max_age: float = 0.2) -> GripperStatus:
        with self._lock:
            self._check()
            reading = self._reading
        if reading is None:  # connect() stores a first reading: cannot happen while connected
            raise StaleObservationError(self._name, "no reading yet")
        age = time.monotonic() - reading.t
        if age > max_age:
            raise StaleObservationError(
                self._name, f"latest reading is {age * 1e3:.0f} ms old (max {max_age * 1e3:.0f})"
            )
        held = (
            not reading.moving
            and abs(reading.current) >= GRASP_CURRENT * self._cap
            and abs(reading.goal - reading.position) > GRASP_TICKS
        )
        return GripperStatus(
            opening=self.calibration.to_opening(reading.position),
            target=self.calibration.to_opening(reading.goal),
            object_detected=held,
            fault="",
            timestamp=reading.t,
        )

    def roundtrip_ms(self) -> RoundTripStats:
        """Median and 99th percentile of the last ≤2000 polling reads (NaN before the first)."""
        with self._lock:
            return RoundTripStats.from_seconds(self._roundtrips)

    def __enter__(self) -> DynamixelGripper:
        self.connect()
        return self

    def __exit__(self, *exc: object) -> None:
        self.disconnect()

    def _check(self) -> None:
        if not self._connected:
            raise DeviceNotConnectedError(self._name, "not connected (call connect())")
        if self._error is not None:
            raise self._error

    # -- start-up

    def _configure(self) -> None:
        where = f"servo {self._id} on {self._port_name}"
        try:
            model = self._call("ping", lambda: self._ph.ping(self._port, self._id))
        except (DeviceTimeoutError, DeviceProtocolError) as e:
            raise DeviceConnectionError(self._name, f"{where} does not answer ping: {e}") from e
        if model != self._model:
            expected, found = MODEL_NAMES.get(self._model, "?"), MODEL_NAMES.get(model, "unknown")
            raise DeviceConnectionError(
                self._name, f"{where} is model {model} ({found}), expected {self._model} ({expected})"
            )
        try:
            self._check_health(expect_torque=None)
            self._write(1, TORQUE_ENABLE, 0)
            self._write(1, OPERATING_MODE, CURRENT_BASED_POSITION)
            limit = self._read(CURRENT_LIMIT, 2)
        except (DeviceTimeoutError, DeviceProtocolError) as e:
            raise DeviceConnectionError(self._name, f"{where} failed during set-up: {e}") from e
        if self._cap > limit:
            raise DeviceConnectionError(
                self._name,
                f"current_limit_ma {self._cap * CURRENT_UNIT_MA:.0f} exceeds the servo's Current_Limit "
                f"({limit * CURRENT_UNIT_MA:.0f} mA)",
            )
        cal = self.calibration
        try:
            self._write(2, GOAL_CURRENT, self._cap)
            present = _signed(self._read(PRESENT_POSITION, 4), 32)
            # Fingers far outside the calibrated travel: a wrong calibration, servo id or horn position (or
            # an encoder wrapped past 0/4095). Targets would drive into a hard stop: refuse, torque still off.
            if not -CALIBRATION_SLACK <= cal.to_opening(present, clip=False) <= 1 + CALIBRATION_SLACK:
                raise DeviceConnectionError(
                    self._name,
                    f"present position {present} ticks is outside the calibrated travel {cal.ticks_closed} "
                    f"(closed) … {cal.ticks_open} (open): recalibrate, or check the servo id and horn",
                )
            self._write(4, GOAL_POSITION, present)  # before torque on: hold where it stands, no jump
            self._write(1, TORQUE_ENABLE, 1)
            self._sync_read = GroupSyncRead(self._port, self._ph, READ_START, READ_LENGTH)
            self._sync_read.addParam(self._id)
            self._sync_write = GroupSyncWrite(self._port, self._ph, GOAL_POSITION, 4)
            reading = self._poll()
        except (DeviceTimeoutError, DeviceProtocolError) as e:
            raise DeviceConnectionError(self._name, f"{where} failed during set-up: {e}") from e
        with self._lock:
            self._reading, self._target = reading, reading.goal

    # -- the I/O thread

    def _run(self) -> None:
        health_every = max(1, round(1.0 / (self._period * HEALTH_HZ)))
        cycle = 0
        next_tick = time.monotonic()
        while not self._stop.is_set():
            try:
                self._cycle(check_health=cycle % health_every == 0)
            except _StopRequestedError:
                return
            except Exception as e:  # stored, never lost with the thread: the next call raises it
                error = e if isinstance(e, RobotError) else DeviceConnectionError(self._name, f"I/O failed: {e!r}")
                log.error("%s", error)  # the error names the device
                with self._lock:
                    self._error = error
                return
            cycle += 1
            next_tick += self._period
            delay = next_tick - time.monotonic()
            if delay < 0:  # behind (a slow bus): carry on from now rather than burst to catch up
                next_tick = time.monotonic()
            else:
                self._stop.wait(delay)

    def _cycle(self, *, check_health: bool) -> None:
        with self._lock:
            target = self._target
            known_goal = self._reading.goal if self._reading is not None else None
        if target is not None and target != known_goal:
            self._send_goal(target)
        reading = self._poll()
        if check_health:
            self._check_health(expect_torque=1)
        with self._lock:
            self._reading = reading

    def _send_goal(self, ticks: int) -> None:
        data = list((ticks & 0xFFFFFFFF).to_bytes(4, "little"))
        if not self._sync_write.changeParam(self._id, data):
            self._sync_write.addParam(self._id, data)
        # no status packet to a broadcast: the next read-back of Goal_Position confirms it
        self._call("sync write Goal_Position", lambda: (None, self._sync_write.txPacket(), 0))

    def _poll(self) -> _Reading:
        def transaction() -> tuple[None, int, int]:
            t0 = time.perf_counter()
            result = self._sync_read.txRxPacket()
            if result == COMM_SUCCESS:
                elapsed = time.perf_counter() - t0
                with self._lock:
                    self._roundtrips.append(elapsed)
            return None, result, 0

        self._call("sync read", transaction)
        get = self._sync_read.getData
        return _Reading(
            goal=_signed(get(self._id, GOAL_POSITION, 4), 32),
            position=_signed(get(self._id, PRESENT_POSITION, 4), 32),
            current=_signed(get(self._id, PRESENT_CURRENT, 2), 16),
            moving=bool(get(self._id, MOVING, 1)),
            t=time.monotonic(),
        )

    def _check_health(self, *, expect_torque: int | None) -> None:
        torque, *_, hardware = self._read_many(HEALTH_START, HEALTH_LENGTH, size=1)
        if hardware:
            raise DeviceFaultError(
                self._name,
                f"servo {self._id} hardware error: {_decode_hardware(hardware)} (Hardware_Error_Status "
                f"0x{hardware:02x}); its torque is off until it is rebooted or power-cycled",
            )
        if expect_torque is not None and torque != expect_torque:
            raise DeviceFaultError(self._name, f"servo {self._id} torque went off (rebooted or lost power?)")

    # -- transactions with retries and typed errors

    def _call(self, what: str, fn: Callable[[], tuple[T, int, int]]) -> T:
        """``fn`` returns the SDK's (value, comm result, status error byte); retried on timeout/corruption."""
        result = COMM_SUCCESS
        for attempt in range(self._retries + 1):
            if attempt and self._stop.is_set():
                raise _StopRequestedError  # disconnect() is waiting: no more retries
            try:
                value, result, error = fn()
            except IO_ERRORS as e:
                raise DeviceConnectionError(self._name, f"serial port {self._port_name} failed: {e}") from e
            if result == COMM_SUCCESS:
                if error & ERRBIT_ALERT and what != "read health":
                    # the alert bit: a hardware error; read its cause so the message says what broke
                    self._check_health(expect_torque=None)
                if error & ~ERRBIT_ALERT:
                    raise DeviceFaultError(self._name, f"{what}: {self._ph.getRxPacketError(error)}")
                return value
            if result not in (COMM_RX_TIMEOUT, COMM_RX_CORRUPT):
                break  # port busy or a failed write: not a transient of the wire
            log.debug("%s: %s attempt %d: %s", self._name, what, attempt + 1, self._ph.getTxRxResult(result))
        message = f"{what} on servo {self._id}: {self._ph.getTxRxResult(result)} ({self._retries + 1} attempts)"
        if result == COMM_RX_TIMEOUT:
            raise DeviceTimeoutError(self._name, message)
        if result == COMM_RX_CORRUPT:
            raise DeviceProtocolError(self._name, message)
        raise DeviceConnectionError(self._name, message)

    def _read(self, address: int, size: int) -> int:
        reader = {1: self._ph.read1ByteTxRx, 2: self._ph.read2ByteTxRx, 4: self._ph.read4ByteTxRx}[size]
        return int(self._call(f"read {address}", lambda: reader(self._port, self._id, address)))

    def _read_many(self, address: int, count: int, size: int = 4) -> list[int]:
        """``count`` consecutive fields of ``size`` bytes in one READ."""
        what = "read health" if address == HEALTH_START else f"read {address}"
        data = self._call(what, lambda: self._ph.readTxRx(self._port, self._id, address, count * size))
        return [int.from_bytes(bytes(data[i * size : (i + 1) * size]), "little") for i in range(count)]

    def _write(self, size: int, address: int, value: int) -> None:
        writer = {1: self._ph.write1ByteTxRx, 2: self._ph.write2ByteTxRx, 4: self._ph.write4ByteTxRx}[size]
        raw = value & ((1 << (8 * size)) - 1)
        self._call(f"write {address}={value}", lambda: (None, *writer(self._port, self._id, address, raw)))

    def _close_port(self) -> None:
        if self._port is not None:
            try:
                self._port.closePort()
            except Exception as e:  # best effort, like the torque off before it
                log.warning("%s: closing %s: %s", self._name, self._port_name, e)
            self._port = None
