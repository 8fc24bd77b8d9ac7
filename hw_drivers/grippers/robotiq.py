"""Robotiq 2F-85 over Modbus RTU (pyserial, our own framing in :mod:`hw_drivers.grippers.modbus`).

``connect()`` opens the port, resets and activates the gripper (rACT 0 then 1, waits for gSTA 3), then
takes the measured position as the first target — so the fingers do not jump to a stale goal on start
— and starts one I/O thread. At ``poll_hz`` that thread writes the latest target when it changed
(FC16 at 1000: rACT|rGTO, rPR, rSP, rFR) and reads the status (FC03 at 2000, 3 registers). The arm's
loop only exchanges values with the thread, so ``set_target``/``status`` never wait on the bus.

Failures: each request is tried ``1 + retries`` times (``timeout`` each); when every try fails the
thread stores a typed error and stops — :class:`DeviceTimeoutError` (no reply), ``DeviceProtocolError``
(malformed replies, Modbus exceptions), :class:`DeviceConnectionError` (the port went away, at once,
no retries), :class:`RobotiqFaultError` (the gripper reports a fault that stops it) — and every later
call raises it. Worst case from the fault to the stored error: ``(1 + retries) * timeout`` plus one
poll period (0.32 s with the defaults).
"""

from __future__ import annotations

import contextlib
import math
import termios
import threading
import time
from collections import deque

import serial

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
from hw_drivers.grippers import modbus
from hw_drivers.grippers.base import GripperStatus, RoundTripStats

COMMAND_ADDRESS = 1000
STATUS_ADDRESS = 2000
STATUS_REGISTERS = 3
ACT, GTO = 0x01, 0x08  # action request bits (rATR 0x10 is never sent: it needs a manual reset)

# gFLT (Robotiq 2F-85 manual, "Fault status"). Priority faults (0x05, 0x07) and the communication
# watchdog (0x09) are reported in ``GripperStatus.fault`` but do not stop the driver; the others stop
# the gripper until a reset and are raised as RobotiqFaultError.
FAULTS = {
    0x05: "action delayed: activation must complete first",
    0x07: "the activation bit must be set before an action",
    0x08: "maximum operating temperature exceeded, wait for cool-down",
    0x09: "no communication for at least 1 s",
    0x0A: "under minimum operating voltage",
    0x0B: "automatic release in progress",
    0x0C: "internal fault",
    0x0D: "activation fault: check for interference",
    0x0E: "overcurrent triggered",
    0x0F: "automatic release completed",
}
NON_FATAL = {0x00, 0x05, 0x07, 0x09}
GSTA = {0: "reset", 1: "activation in progress", 2: "unused", 3: "activated"}
_IO_ERRORS = (serial.SerialException, OSError, termios.error)


class RobotiqFaultError(DeviceFaultError):
    """The gripper reports fault ``code`` (gFLT; ``kflt`` the controller's code)."""

    def __init__(self, device: str, code: int, kflt: int = 0) -> None:
        super().__init__(device, f"gripper fault {decode_fault(code, kflt)}")
        self.code = code
        self.kflt = kflt


def decode_fault(gflt: int, kflt: int = 0) -> str:
    """A readable fault: ``""`` for none, else ``"0x0A: under minimum operating voltage"``."""
    parts = []
    if gflt:
        parts.append(f"{gflt:#04x}: {FAULTS.get(gflt, 'unknown fault')}")
    if kflt:
        parts.append(f"controller fault kFLT {kflt:#04x}")
    return "; ".join(parts)


def opening_to_position(opening: float, position_open: int = 0, position_closed: int = 255) -> int:
    """The rPR (0 … 255) for a normalised opening (1 open … 0 closed), clipped to the calibration."""
    _check_calibration(position_open, position_closed)
    if not math.isfinite(opening):
        raise ValueError(f"opening: expected a finite number, got {opening!r}")
    opening = min(1.0, max(0.0, opening))
    return round(position_open + (1.0 - opening) * (position_closed - position_open))


def position_to_opening(position: int, position_open: int = 0, position_closed: int = 255) -> float:
    """The normalised opening for a gPO, clipped to 0 … 1 (a 2F-85 reads a few counts past its ends)."""
    _check_calibration(position_open, position_closed)
    opening = 1.0 - (position - position_open) / (position_closed - position_open)
    return min(1.0, max(0.0, opening))


def _check_calibration(position_open: int, position_closed: int) -> None:
    if not 0 <= position_open < position_closed <= 255:
        raise ValueError(
            f"expected 0 ≤ position_open < position_closed ≤ 255 (Robotiq counts grow as the fingers "
            f"close), got position_open={position_open}, position_closed={position_closed}"
        )


def _check_byte(name: str, value: int) -> int:
    if not 0 <= value <= 255:
        raise ValueError(f"{name}: expected 0 … 255, got {value}")
    return value


class RobotiqGripper:
    """A Robotiq 2F-85 (or 2F-140, Hand-E: same registers) on a serial port; implements ``Gripper``."""

    def __init__(
        self,
        name: str,
        port: str,
        *,
        slave_id: int = 9,
        baudrate: int = 115200,
        speed: int = 255,
        force: int = 150,
        position_open: int = 0,
        position_closed: int = 255,
        poll_hz: float = 50,
        timeout: float = 0.1,
        retries: int = 2,
        activation_timeout: float = 5.0,
    ) -> None:
        _check_calibration(position_open, position_closed)
        if not 1 <= slave_id <= 247:
            raise ValueError(f"slave_id: expected 1 … 247, got {slave_id}")
        if poll_hz <= 0 or timeout <= 0 or activation_timeout <= 0 or retries < 0:
            raise ValueError("poll_hz, timeout and activation_timeout must be > 0 and retries ≥ 0")
        self._name, self.port, self.slave_id, self.baudrate = name, port, slave_id, baudrate
        self.speed, self.force = _check_byte("speed", speed), _check_byte("force", force)
        self.position_open, self.position_closed = position_open, position_closed
        self.period, self.timeout, self.retries = 1.0 / poll_hz, timeout, retries
        self.activation_timeout = activation_timeout
        self._serial: serial.Serial | None = None
        self._thread: threading.Thread | None = None
        self._stop = threading.Event()
        self._lock = threading.Lock()  # guards the fields below; never held during I/O
        self._target = 1.0
        self._target_seq = 0
        self._sent_target = 1.0  # the last target written to the device (reported in the status)
        self._status: GripperStatus | None = None
        self._error: RobotError | None = None
        self._roundtrips: deque[float] = deque(maxlen=2000)

    # --------------------------------------------------------------------------------- Gripper contract

    @property
    def name(self) -> str:
        return self._name

    @property
    def is_connected(self) -> bool:
        return self._serial is not None and self._error is None

    def connect(self) -> None:
        if self._serial is not None:
            raise DeviceAlreadyConnectedError(self._name, f"already connected on {self.port}")
        try:
            port = serial.Serial(self.port, self.baudrate, bytesize=8, parity="N", stopbits=1, timeout=self.timeout)
        except _IO_ERRORS as e:
            raise DeviceConnectionError(self._name, f"cannot open serial port {self.port}: {e}") from e
        self._serial = port
        self._error = None
        try:
            status = self._activate()
            opening = position_to_opening(status[4], self.position_open, self.position_closed)
            # Hold where the fingers are: rPR = gPO (the lesson of violent start-up motion).
            self._write_command(ACT | GTO, status[4])
            with self._lock:
                self._target, self._target_seq, self._sent_target = opening, 0, opening
                self._status = self._to_status(status, opening)
        except BaseException:
            self._close_port()
            raise
        self._stop.clear()
        self._thread = threading.Thread(target=self._run, name=f"robotiq-{self._name}", daemon=True)
        self._thread.start()

    def disconnect(self) -> None:
        """Stop the I/O thread and close the port; the gripper stays activated and holds its position."""
        self._stop.set()
        if self._thread is not None and self._thread is not threading.current_thread():
            self._thread.join(2.0 + (1 + self.retries) * self.timeout)
        self._thread = None
        self._close_port()

    def set_target(self, opening: float) -> float:
        if not math.isfinite(opening):
            raise ValueError(f"{self._name}: opening must be finite, got {opening!r}")
        clipped = min(1.0, max(0.0, float(opening)))
        with self._lock:
            self._raise_if_unusable()
            if clipped != self._target:
                self._target = clipped
                self._target_seq += 1
        return clipped

    def status(self, max_age: float = 0.2) -> GripperStatus:
        with self._lock:
            self._raise_if_unusable()
            status = self._status
        assert status is not None  # set by connect() before the thread starts
        age = time.monotonic() - status.timestamp
        if age > max_age:
            raise StaleObservationError(
                self._name, f"gripper status is {age * 1e3:.0f} ms old (max {max_age * 1e3:.0f})"
            )
        return status

    def roundtrip_ms(self) -> RoundTripStats:
        """Status-read round trips so far (request written → reply parsed): count, median and p99 [ms]."""
        with self._lock:
            return RoundTripStats.from_seconds(self._roundtrips)

    def __enter__(self) -> RobotiqGripper:
        self.connect()
        return self

    def __exit__(self, *exc: object) -> None:
        self.disconnect()

    # ---------------------------------------------------------------------------------------- internals

    def _raise_if_unusable(self) -> None:
        if self._error is not None:
            raise self._error
        if self._serial is None:
            raise DeviceNotConnectedError(self._name, "not connected (call connect())")

    def _close_port(self) -> None:
        port, self._serial = self._serial, None
        if port is not None:
            with contextlib.suppress(*_IO_ERRORS):  # a port already gone has nothing left to release
                port.close()

    def _to_status(self, raw: bytes, target: float) -> GripperStatus:
        return GripperStatus(
            opening=position_to_opening(raw[4], self.position_open, self.position_closed),
            target=target,
            object_detected=(raw[0] >> 6) & 0x03 in (1, 2),
            fault=decode_fault(raw[2] & 0x0F, raw[2] >> 4),
            timestamp=time.monotonic(),
        )

    def _check_fault(self, raw: bytes) -> None:
        gflt, kflt = raw[2] & 0x0F, raw[2] >> 4
        if gflt not in NON_FATAL:
            raise RobotiqFaultError(self._name, gflt, kflt)

    def _activate(self) -> bytes:
        """Reset then activate (the manual's sequence); the status once gSTA is 3."""
        self._write_command(0, 0)
        self._write_command(ACT, 0)
        deadline = time.monotonic() + self.activation_timeout
        while True:
            raw = self._read_status()
            self._check_fault(raw)
            if (raw[0] >> 4) & 0x03 == 3:
                return raw
            if time.monotonic() > deadline:
                state = GSTA[(raw[0] >> 4) & 0x03]
                raise DeviceTimeoutError(
                    self._name, f"not activated within {self.activation_timeout} s (gSTA: {state})"
                )
            time.sleep(0.01)

    def _write_command(self, action: int, position: int) -> None:
        registers = modbus.bytes_to_registers(bytes([action, 0, 0, position, self.speed, self.force]))
        self._transact(modbus.write_request(self.slave_id, COMMAND_ADDRESS, registers), modbus.WRITE_MULTIPLE)

    def _read_status(self) -> bytes:
        request = modbus.read_request(self.slave_id, STATUS_ADDRESS, STATUS_REGISTERS)
        t0 = time.perf_counter()
        data = self._transact(request, modbus.READ_HOLDING)
        elapsed = time.perf_counter() - t0
        if len(data) != 2 * STATUS_REGISTERS:
            raise DeviceProtocolError(self._name, f"status of {len(data)} bytes, expected 6")
        with self._lock:
            self._roundtrips.append(elapsed)
        return data

    def _transact(self, request: bytes, function: int) -> bytes:
        """One request/reply with retries; raises the typed error once the retries are spent."""
        port = self._serial
        if port is None:
            raise DeviceNotConnectedError(self._name, "not connected")
        last: RobotError | None = None
        malformed = False
        for _ in range(1 + self.retries):
            try:
                port.reset_input_buffer()  # a late reply to a timed-out request must not be read as ours
                port.write(request)
                frame = self._read_frame(port)
            except _IO_ERRORS as e:
                raise DeviceConnectionError(self._name, f"serial port {self.port} lost: {e}") from e
            if frame is None:
                last = DeviceTimeoutError(self._name, f"no reply from slave {self.slave_id} on {self.port}")
                continue
            try:
                return modbus.parse_reply(frame, slave=self.slave_id, function=function, device=self._name)
            except modbus.ModbusExceptionError:
                raise  # the device understood and refused: retrying will not help
            except DeviceProtocolError as e:
                last, malformed = e, True
        assert last is not None
        tries = f"after {1 + self.retries} tries of {self.timeout * 1e3:.0f} ms"
        if malformed:
            raise DeviceProtocolError(self._name, f"{last.args[0]} ({tries})")
        raise DeviceTimeoutError(self._name, f"{last.args[0]} ({tries})")

    def _read_frame(self, port: serial.Serial) -> bytes | None:
        """A reply, or None if nothing came within the timeout. Every reply is ≥ 5 bytes long."""
        head: bytes = port.read(5)
        if not head:
            return None
        try:
            n = modbus.reply_length(head, self._name)
        except DeviceProtocolError:
            return head  # out of step; parse_reply says why
        if n is None or len(head) >= n:
            return head
        rest: bytes = port.read(n - len(head))
        return head + rest

    def _run(self) -> None:
        """The I/O thread: write the target when it changed, read the status, every period."""
        sent_seq = 0
        next_tick = time.monotonic()
        while not self._stop.is_set():
            try:
                with self._lock:
                    target, seq = self._target, self._target_seq
                if seq != sent_seq:
                    position = opening_to_position(target, self.position_open, self.position_closed)
                    self._write_command(ACT | GTO, position)
                    sent_seq = seq
                    self._sent_target = target  # only this thread writes it once running
                raw = self._read_status()
                status = self._to_status(raw, self._sent_target)
                with self._lock:
                    self._status = status
                self._check_fault(raw)
                if (raw[0] >> 4) & 0x03 != 3:  # a brownout or another master reset it: it will not move
                    state = GSTA[(raw[0] >> 4) & 0x03]
                    raise DeviceFaultError(self._name, f"gripper no longer activated (gSTA: {state}); reconnect")
            except RobotError as e:
                with self._lock:
                    self._error = e
                return
            next_tick += self.period
            delay = next_tick - time.monotonic()
            if delay < 0:  # fell behind (retries): restart the schedule rather than burst
                next_tick, delay = time.monotonic(), 0.0
            self._stop.wait(delay)
