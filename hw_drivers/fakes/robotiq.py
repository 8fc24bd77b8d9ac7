"""A protocol-level fake Robotiq 2F-85: Modbus RTU (115200 8N1) on a pseudo-terminal, fingers on a RigBackend.

Registers (Robotiq 2F-85 manual; castetsb/pyRobotiqGripper; ros-industrial-attic/robotiq):

* command, FC16 at 1000 … 1002 (6 bytes): byte0 action request ``rACT`` bit0, ``rGTO`` bit3, ``rATR``
  bit4; bytes 1-2 reserved; byte3 ``rPR`` position request (0 open … 255 closed); byte4 ``rSP`` speed;
  byte5 ``rFR`` force;
* status, FC03 or FC04 at 2000 … 2002 (6 bytes): byte0 ``gACT`` bit0, ``gGTO`` bit3, ``gSTA`` bits 4-5
  (0 reset, 1 activating, 3 activated), ``gOBJ`` bits 6-7 (0 moving, 1/2 stopped on an object while
  opening/closing, 3 at the requested position); byte2 fault (``gFLT`` low nibble, ``kFLT`` high
  nibble); byte3 ``gPR`` echo of rPR; byte4 ``gPO`` position; byte5 ``gCU`` current.

Behaviour modelled on the real device: a rising edge of rACT starts an activation that completes after
``activation_time`` (gSTA 1 then 3) and clears non-persistent faults; rACT 0 resets. A position request
(rGTO 1) before activation does not move the fingers: with rACT 0 it raises the priority fault 0x07,
during activation 0x05 and the request is carried out once activation completes (the registers still
hold it). Frames with a bad CRC or for another slave get no reply (Modbus); broadcast (slave 0) writes
are applied silently; unknown functions and addresses get exception replies 0x01 / 0x02.

Stroke: position counts map linearly to the backend's normalised opening, ``opening = 1 - p / closed_count``
with requests above ``closed_count`` clamped (fingers touching). The default ``closed_count`` 255 matches
the driver's default calibration (``position_closed=255``); a real 2F-85 reports about 230 when its
fingers touch over the 85 mm stroke — pass ``closed_count=230`` to fake that and calibrate the driver
with ``position_closed=230``. Speed and force are echoed but not modelled (the backend sets the slew);
``gCU`` is a plausible stand-in (force/4 while holding an object, a few counts while moving).

Faults (``faults``, :mod:`hw_drivers.fakes.faults`): ``drop`` — a request is lost (no reply, not applied);
``corrupt`` — the reply's last byte is flipped (bad CRC); ``stall`` — nothing is answered; ``disconnect``
— the pty is hung up for good (the driver sees an I/O error). Device faults: :meth:`set_fault` (e.g.
0x0A under-voltage, 0x0B automatic release in progress, 0x0F automatic release completed); a major
fault (≥ 0x08) stops the fingers where they are.
"""

from __future__ import annotations

import threading
import time
from types import TracebackType

from hw_drivers.fakes.backend import RigBackend, check_side
from hw_drivers.fakes.faults import FaultSwitch
from hw_drivers.fakes.pty import PtyPair
from hw_drivers.grippers import modbus

COMMAND_ADDRESS, COMMAND_REGISTERS = 1000, 3
STATUS_ADDRESS, STATUS_REGISTERS = 2000, 3
KNOWN_FUNCTIONS = (0x03, 0x04, 0x05, 0x06, 0x0F, 0x10)
# A partial frame followed by this much silence is discarded (RTU frames end in 3.5 character times;
# a pty delivers a frame in one burst, so anything this late is a broken frame).
FRAME_GAP = 0.02
# The fingers count as stopped after this long without moving (gOBJ 1/2 instead of 0).
SETTLE_TIME = 0.1
MOTION_EPS = 0.002  # ≈ half a count: less than this in SETTLE_TIME is standing still
AT_POSITION_COUNTS = 2.0  # |gPO - goal| within this many counts → gOBJ 3
# Automatic release counts as completed (0x0F) from this opening on: a quarter count short of fully open,
# since a simulated servo approaches 1.0 without always landing on it exactly.
RELEASED_OPENING = 0.999


class FakeRobotiqGripper:
    """A fake 2F-85 on a pty; the driver opens :attr:`path`. Use :meth:`start`/:meth:`stop` or ``with``."""

    def __init__(
        self,
        backend: RigBackend,
        side: str,
        slave_id: int = 9,
        faults: FaultSwitch | None = None,
        *,
        activation_time: float = 0.5,
        closed_count: int = 255,
        tick: float = 0.005,
    ) -> None:
        if not 1 <= slave_id <= 247:
            raise ValueError(f"slave_id: expected 1 … 247, got {slave_id}")
        if not 1 <= closed_count <= 255:
            raise ValueError(f"closed_count: expected 1 … 255, got {closed_count}")
        if activation_time < 0 or tick <= 0:
            raise ValueError("activation_time must be ≥ 0 and tick > 0")
        self.backend = backend
        self.side = check_side(side)
        self.slave_id = slave_id
        self.faults = faults if faults is not None else FaultSwitch()
        self.activation_time = activation_time
        self.closed_count = closed_count
        self._tick = tick
        self._pty = PtyPair()
        self._lock = threading.Lock()
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        self.error: BaseException | None = None  # why the device thread died, if it did
        self.requests_served = 0
        # device state (under _lock)
        self._command = bytearray(6)
        self._activation_start: float | None = None
        self._activated = False
        self._fault = 0  # gFLT set by a test (or automatic release)
        self._fault_persistent = False
        self._kflt = 0
        self._priority_fault = 0  # 0x05 / 0x07, raised by the device itself
        self._goal: float | None = None  # the opening the fingers are driven to, None = not driven
        self._opening = backend.gripper_opening(self.side)
        self._moved_from = self._opening
        self._last_move = time.monotonic()
        self._goal_since = self._last_move

    # ------------------------------------------------------------------------------------------ lifecycle

    @property
    def path(self) -> str:
        return self._pty.path

    def start(self) -> FakeRobotiqGripper:
        if self._thread is None:
            self._thread = threading.Thread(target=self._run, name=f"fake-robotiq-{self.side}", daemon=True)
            self._thread.start()
        return self

    def stop(self) -> None:
        self._stop.set()
        if self._thread is not None and self._thread is not threading.current_thread():
            self._thread.join(2.0)
        self._pty.close()

    def __enter__(self) -> FakeRobotiqGripper:
        return self.start()

    def __exit__(
        self, exc_type: type[BaseException] | None, exc: BaseException | None, tb: TracebackType | None
    ) -> None:
        self.stop()

    # ------------------------------------------------------------------------------------- test controls

    def set_fault(self, code: int, *, persistent: bool = False, kflt: int = 0) -> None:
        """Report gFLT ``code`` (and controller fault ``kflt``). A non-persistent fault is cleared by the
        next reset + activation (rACT rising edge, as the manual prescribes); a persistent one (the
        condition is still there, e.g. low supply voltage) only by :meth:`clear_fault`."""
        if not 0 <= code <= 0x0F or not 0 <= kflt <= 0x0F:
            raise ValueError(f"fault codes are 4-bit: gFLT {code:#x}, kFLT {kflt:#x}")
        with self._lock:
            self._fault, self._fault_persistent, self._kflt = code, persistent, kflt
            if code >= 0x08:
                self._hold()

    def clear_fault(self) -> None:
        with self._lock:
            self._fault, self._fault_persistent, self._kflt = 0, False, 0

    def power_cycle(self) -> None:
        """A brownout: the registers clear and the gripper is back in reset (gSTA 0) until re-activated."""
        with self._lock:
            self._command[:] = bytes(6)
            self._activation_start, self._activated, self._priority_fault = None, False, 0
            self._hold()

    @property
    def command(self) -> bytes:
        """The 6 command bytes last written (rACT/rGTO/rATR, reserved×2, rPR, rSP, rFR)."""
        with self._lock:
            return bytes(self._command)

    def status_bytes(self) -> bytes:
        """The 6 status bytes a read of 2000 … 2002 would return now."""
        with self._lock:
            self._update(time.monotonic())
            return self._status()

    # ----------------------------------------------------------------------------------------- the model

    def _count_to_opening(self, count: int) -> float:
        return 1.0 - min(count, self.closed_count) / self.closed_count

    def _hold(self) -> None:
        """Stop the fingers where they are (reset, stop request, major fault)."""
        if self._goal is not None:
            self._opening = self.backend.gripper_opening(self.side)  # fresh: a stale sample would jerk back
            self.backend.set_gripper_target(self.side, self._opening)
            self._goal = None

    def _major_fault(self) -> bool:
        return self._fault >= 0x08

    def _apply_command(self, before: bytes, now: float) -> None:
        """A write changed the command registers: react to rACT edges and requests."""
        act, was = self._command[0], before[0]
        if act & 0x01 and not was & 0x01:  # rising edge of rACT: (re)activation
            if not self._fault_persistent:
                self._fault = 0
                self._kflt = 0
            self._priority_fault = 0
            self._activation_start, self._activated = now, False
        elif not act & 0x01:  # reset
            self._activation_start, self._activated = None, False
            self._hold()
        if act & 0x08 and not self._activated:
            self._priority_fault = 0x07 if not act & 0x01 else 0x05

    def _update(self, now: float) -> None:
        """Advance activation, drive the backend toward the request, track motion. Under ``_lock``."""
        if (
            self._activation_start is not None
            and not self._activated
            and not self._major_fault()
            and now - self._activation_start >= self.activation_time
        ):
            self._activated = True
            self._priority_fault = 0
        opening = self.backend.gripper_opening(self.side)
        # Motion is measured from where the fingers last counted as moving, not sample to sample: a slow
        # slew moves less than any threshold in one tick but still far in SETTLE_TIME.
        if abs(opening - self._moved_from) > MOTION_EPS:
            self._last_move, self._moved_from = now, opening
        self._opening = opening
        act = self._command[0]
        goal: float | None = None
        if act & 0x10 and act & 0x01:  # automatic release: open, report 0x0B then 0x0F
            goal = 1.0
            if not self._major_fault() or self._fault in (0x0B, 0x0F):
                self._fault = 0x0F if opening >= RELEASED_OPENING else 0x0B
        elif self._activated and act & 0x08 and not self._major_fault():
            goal = self._count_to_opening(self._command[3])
        if goal is None:
            self._hold()
        elif goal != self._goal:
            self.backend.set_gripper_target(self.side, goal)
            self._goal, self._goal_since = goal, now

    def _status(self) -> bytes:
        act = self._command[0]
        g_act = act & 0x01
        g_gto = 1 if self._activated and act & 0x08 else 0
        g_sta = 3 if self._activated else (1 if self._activation_start is not None else 0)
        g_obj = 0
        now = time.monotonic()
        if g_gto and self._goal is not None:
            if abs(self._opening - self._goal) * self.closed_count <= AT_POSITION_COUNTS:
                g_obj = 3
            elif now - self._last_move > SETTLE_TIME and now - self._goal_since > SETTLE_TIME:
                g_obj = 2 if self._goal < self._opening else 1
        moving = now - self._last_move < SETTLE_TIME
        current = self._command[5] // 4 if g_obj in (1, 2) else (5 if moving else 0)
        fault = self._fault or self._priority_fault
        position = round((1.0 - self._opening) * self.closed_count)
        return bytes(
            [
                g_act | g_gto << 3 | g_sta << 4 | g_obj << 6,
                0,
                self._kflt << 4 | fault,
                self._command[3],
                max(0, min(255, position)),
                current,
            ]
        )

    # ------------------------------------------------------------------------------------------ the bus

    def _answer(self, frame: bytes) -> bytes | None:
        """The reply to one request frame (None: no reply)."""
        if not modbus.crc_ok(frame):
            return None  # Modbus: a device never answers a frame it could not read
        slave = frame[0]
        if slave not in (self.slave_id, 0):
            return None
        request = modbus.parse_request(frame)
        now = time.monotonic()
        with self._lock:
            self._update(now)
            if isinstance(request, int):
                reply = modbus.exception_reply(slave, frame[1], request)
            elif request.function in (modbus.READ_HOLDING, modbus.READ_INPUT):
                offset = request.address - STATUS_ADDRESS
                if offset < 0 or offset + request.count > STATUS_REGISTERS:
                    reply = modbus.exception_reply(slave, request.function, modbus.ILLEGAL_ADDRESS)
                else:
                    data = self._status()[2 * offset : 2 * (offset + request.count)]
                    reply = modbus.read_reply(slave, request.function, data)
            else:
                offset = request.address - COMMAND_ADDRESS
                if offset < 0 or offset + request.count > COMMAND_REGISTERS:
                    reply = modbus.exception_reply(slave, request.function, modbus.ILLEGAL_ADDRESS)
                else:
                    before = bytes(self._command)
                    self._command[2 * offset : 2 * offset + len(request.data)] = request.data
                    self._apply_command(before, now)
                    self._update(now)
                    reply = modbus.write_reply(slave, request.address, request.count)
            self.requests_served += 1
        return None if slave == 0 else reply

    def _next_frame(self, buf: bytearray) -> bytes | None:
        """Cut one complete request off the front of ``buf`` (None: incomplete)."""
        if len(buf) >= 2 and buf[1] not in KNOWN_FUNCTIONS:
            frame = bytes(buf)  # unknown function: its length is unknowable, take the burst
            buf.clear()
            return frame
        n = modbus.request_length(bytes(buf))
        if n is None or len(buf) < n:
            return None
        frame = bytes(buf[:n])
        del buf[:n]
        return frame

    def _run(self) -> None:
        buf = bytearray()
        last_rx = time.monotonic()
        try:
            while not self._stop.is_set():
                if self.faults.active("disconnect"):
                    self._pty.close()  # hung up for good, like an unplugged USB adapter
                    return
                chunk = self._pty.read(256, timeout=self._tick)
                now = time.monotonic()
                if chunk:
                    buf += chunk
                    last_rx = now
                elif buf and now - last_rx > FRAME_GAP:
                    buf.clear()
                with self._lock:
                    self._update(now)
                while (frame := self._next_frame(buf)) is not None:
                    if self.faults.active("stall") or self.faults.active("drop"):
                        continue  # lost: neither applied nor answered
                    reply = self._answer(frame)
                    if reply is None:
                        continue
                    if self.faults.active("corrupt"):
                        reply = reply[:-1] + bytes([reply[-1] ^ 0xFF])
                    self._pty.write(reply)
        except BaseException as e:  # a dead backend: the device goes silent and hangs up
            self.error = e
            self._pty.close()
