"""``URArm``: one Universal Robots arm over RTDE (``ur_rtde``), implementing :class:`hw_drivers.arm.Arm`.

The ur_rtde interfaces live in a worker process of their own (:mod:`hw_drivers.ur.worker`; spawn context)
because their constructors hold the GIL. The worker runs the servoJ loop; this side only touches shared
memory (:mod:`hw_drivers.ur.shared`), so :meth:`state` and :meth:`set_target` never block, and talks to the
worker over a pipe for the rare blocking requests (recover, disconnect).

Errors (all name the arm): ``ProtectiveStopError`` / ``EmergencyStopError`` / ``SafetyStopError`` from the
safety bits; ``DeviceConnectionError`` when connecting fails after the retries or the connection is lost;
``DeviceTimeoutError`` when the RTDE stream goes silent or the worker stops answering; ``DeviceProtocolError``
on implausible data; ``DeviceFaultError`` when the control script stopped without a safety stop (e.g. the
controller's watchdog, or someone pressed stop). After any of these the worker no longer commands the arm
and the controller's watchdog stops the program; :meth:`recover` is the only way back.
"""

from __future__ import annotations

import contextlib
import multiprocessing as mp
import threading
import time
from multiprocessing.connection import Connection
from multiprocessing.process import BaseProcess
from types import TracebackType
from typing import Any

import numpy as np
from numpy.typing import NDArray

from hw_drivers.arm import ArmState
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
    SafetyStopError,
    StaleObservationError,
)
from hw_drivers.ur import shared as S
from hw_drivers.ur import worker

_ERRORS: dict[int, tuple[type[RobotError], str]] = {
    S.PROTECTIVE_STOP: (ProtectiveStopError, "protective stop (call recover() once the cause is cleared)"),
    S.EMERGENCY_STOP: (EmergencyStopError, "emergency stop (release it on the robot, then recover())"),
    S.SAFETY_STOP: (SafetyStopError, "safety stop"),
    S.CONNECTION_LOST: (DeviceConnectionError, "connection to the controller lost"),
    S.STREAM_TIMEOUT: (DeviceTimeoutError, "RTDE stream silent"),
    S.PROTOCOL_ERROR: (DeviceProtocolError, "implausible RTDE data"),
    S.SCRIPT_STOPPED: (DeviceFaultError, "the control script stopped (watchdog, dashboard stop or controller)"),
    S.CLOSED: (DeviceConnectionError, "the worker closed the connection"),
}
_RECONNECT = (S.CONNECTION_LOST, S.STREAM_TIMEOUT, S.PROTOCOL_ERROR, S.CLOSED)


class URArm:
    """A UR arm at ``host`` streamed with servoJ at ``servo_rate_hz`` from its own process.

    ``max_joint_speed`` [rad/s] caps how fast the commanded setpoint moves toward a target (any joint);
    ``watchdog_hz`` is the controller watchdog's minimum input rate; ``stream_timeout`` [s] of RTDE silence
    is a fault; ``worker_timeout`` [s] without a loop heartbeat means the worker hangs.
    """

    def __init__(
        self,
        name: str,
        host: str,
        *,
        servo_rate_hz: float = 500.0,
        lookahead_time: float = 0.1,
        gain: float = 300.0,
        connect_timeout: float = 10.0,
        retries: int = 2,
        max_joint_speed: float = 1.0,
        watchdog_hz: float = 10.0,
        stream_timeout: float = 0.5,
        worker_timeout: float = 1.0,
        command_timeout: float = 20.0,
    ) -> None:
        if not 0.03 <= lookahead_time <= 0.2:
            raise ValueError(f"lookahead_time: expected 0.03 … 0.2 s (servoJ's range), got {lookahead_time}")
        if not 100 <= gain <= 2000:
            raise ValueError(f"gain: expected 100 … 2000 (servoJ's range), got {gain}")
        if servo_rate_hz <= 0 or max_joint_speed <= 0 or watchdog_hz <= 0 or retries < 0:
            raise ValueError("servo_rate_hz, max_joint_speed and watchdog_hz must be > 0, retries >= 0")
        self._name = name
        self._cfg = S.WorkerConfig(
            name=name,
            host=host,
            servo_rate_hz=servo_rate_hz,
            lookahead_time=lookahead_time,
            gain=gain,
            max_joint_speed=max_joint_speed,
            watchdog_hz=watchdog_hz,
            stream_timeout=stream_timeout,
            attempts=retries + 1,
            retry_delay=0.2,
        )
        self._connect_timeout = connect_timeout
        self._worker_timeout, self._command_timeout = worker_timeout, command_timeout
        self._proc: BaseProcess | None = None
        self._conn: Connection | None = None
        self._state_raw: Any = None
        self._lock = threading.Lock()  # one pipe request at a time
        self._busy = False  # a blocking request is running: the loop's heartbeat pauses

    # -- Arm protocol

    @property
    def name(self) -> str:
        return self._name

    @property
    def host(self) -> str:
        return self._cfg.host

    @property
    def is_connected(self) -> bool:
        return self._proc is not None

    def connect(self) -> None:
        if self._proc is not None:
            raise DeviceAlreadyConnectedError(self._name, "already connected")
        ctx = mp.get_context("spawn")
        self._state_raw = ctx.RawArray("d", S.STATE_SIZE)
        self._target_raw = ctx.RawArray("d", S.TARGET_SIZE)
        self._ring_raw = ctx.RawArray("d", S.RING)
        self._state, self._target = S.view(self._state_raw), S.view(self._target_raw)
        self._state[S.STATUS] = S.STARTING
        parent, child = ctx.Pipe()
        proc = ctx.Process(
            target=worker.main,
            args=(child, self._state_raw, self._target_raw, self._ring_raw, self._cfg),
            name=f"ur-arm-{self._name}",
            daemon=True,
        )
        proc.start()
        child.close()
        self._proc, self._conn = proc, parent
        # The worker retries quick failures itself; a hung attempt (a host that accepts but never answers)
        # is cut off here. Spawning the interpreter takes a moment on top.
        budget = self._connect_timeout * self._cfg.attempts + 5.0
        try:
            reply = self._receive(budget, "connect")
        except RobotError as e:
            self._teardown(grace=0.0)
            raise DeviceConnectionError(self._name, f"could not connect to {self.host}: {e}") from e
        if reply[0] != "ok":
            self._teardown(grace=1.0)
            raise DeviceConnectionError(self._name, str(reply[2]))

    def disconnect(self) -> None:
        """servoStop + stopScript (over a live stream; else the controller watchdog stops the arm), then close."""
        if self._proc is None:
            return
        with self._lock:
            if self._proc.is_alive() and self._conn is not None:
                try:
                    self._conn.send(("disconnect",))
                    self._receive(5.0, "disconnect")
                except RobotError:
                    pass  # a hung or dead worker: the teardown kills it and the watchdog stops the arm
        self._teardown(grace=2.0)

    def state(self, max_age: float = 0.1) -> ArmState:
        snap = self._snapshot()
        age = time.monotonic() - snap[S.T_FRESH]
        if age > max_age:
            raise StaleObservationError(self._name, f"latest joint reading is {age * 1e3:.0f} ms old (max {max_age})")
        bits = int(snap[S.SAFETY_BITS])
        return ArmState(
            q=snap[S.Q].copy(), qd=snap[S.QD].copy(), timestamp=float(snap[S.T_FRESH]), safety=S.decode_safety(bits)
        )

    def set_target(self, q: NDArray[np.floating]) -> None:
        self._snapshot()  # raises if the arm is stopped or the link is down
        self._write_target(S.TRACK, self._cfg.max_joint_speed, self._as_q(q))

    def move_to(self, q: NDArray[np.floating], speed: float, timeout: float, tolerance: float = 2e-3) -> None:
        """Move along a straight line in joint space, no joint faster than ``speed`` rad/s, until within
        ``tolerance`` rad; on timeout the arm is stopped and ``DeviceTimeoutError`` raised."""
        goal = self._as_q(q)
        if not speed > 0:
            raise ValueError(f"speed: expected > 0 rad/s, got {speed}")
        self._snapshot()
        self._write_target(S.TRACK, speed, goal)
        deadline = time.monotonic() + timeout
        while True:
            snap = self._snapshot()
            if np.max(np.abs(snap[S.SETPOINT] - goal)) < 1e-9 and np.max(np.abs(snap[S.Q] - goal)) < tolerance:
                return
            if time.monotonic() > deadline:
                self.stop()
                error = float(np.max(np.abs(snap[S.Q] - goal)))
                raise DeviceTimeoutError(self._name, f"move_to not done within {timeout} s ({error:.4f} rad away)")
            time.sleep(0.005)

    def stop(self) -> None:
        """Hold the current setpoint (the servo loop stops moving it); a no-op when not connected or failed."""
        if self._proc is not None:
            self._write_target(S.HOLD, 0.0, np.zeros(6))

    def recover(self) -> None:
        """Protective stop / stopped script: dashboard close popups, unlock, restart the control script.

        A lost, silent or garbled connection is recovered by reconnecting. An engaged emergency stop raises
        ``EmergencyStopError`` (it is released by a person on the robot, never by software).
        """
        if self._proc is None:
            raise DeviceNotConnectedError(self._name, "not connected")
        status = int(S.seq_read(self._state)[S.STATUS])
        if status in _RECONNECT or not self._proc.is_alive():
            self._teardown(grace=0.0)  # the worker no longer commands the arm; its ur_rtde threads may hang
            self.connect()
            return
        with self._lock:
            assert self._conn is not None
            self._busy = True
            try:
                self._write_target(S.HOLD, 0.0, np.zeros(6))
                self._conn.send(("recover",))
                reply = self._receive(self._command_timeout, "recover")
            finally:
                self._busy = False
        if reply[0] != "ok":
            error, _ = _ERRORS.get(int(reply[1]), (DeviceFaultError, ""))
            raise error(self._name, f"recover failed: {reply[2]}")

    # -- extras

    def servo_stats(self) -> S.ServoStats:
        """Servo-loop timing since connect or :meth:`reset_servo_stats` (the last ``RING`` periods for percentiles)."""
        snap = self._snapshot(check=False)
        periods = np.sort(self._ring_periods(snap)) * 1e3
        n = len(periods)
        window = time.monotonic() - snap[S.STATS_T0]

        def pct(p: float) -> float:
            return float(np.percentile(periods, p)) if n else float("nan")

        return S.ServoStats(
            rate_hz=float(snap[S.CYCLES] / window) if window > 0 else 0.0,
            period_p50_ms=pct(50),
            period_p99_ms=pct(99),
            period_max_ms=float(periods[-1]) if n else float("nan"),
            missed_periods=int(snap[S.MISSED]),
            cycles=int(snap[S.CYCLES]),
            window_s=float(window),
        )

    def reset_servo_stats(self) -> None:
        self._snapshot(check=False)
        self._target[S.T_STATS_RESET] += 1

    def __enter__(self) -> URArm:
        self.connect()
        return self

    def __exit__(self, t: type[BaseException] | None, e: BaseException | None, tb: TracebackType | None) -> None:
        self.disconnect()

    def __del__(self) -> None:
        # A forgotten disconnect(): kill the worker; the controller watchdog stops the arm.
        if getattr(self, "_proc", None) is not None:
            with contextlib.suppress(Exception):
                self._teardown(grace=0.0)

    # -- internals

    def _as_q(self, q: NDArray[np.floating]) -> NDArray[np.float64]:
        arr = np.asarray(q, dtype=np.float64)
        if arr.shape != (6,) or not np.all(np.isfinite(arr)):
            raise ValueError(f"{self._name}: expected 6 finite joint angles, got {q!r}")
        return arr

    def _write_target(self, mode: float, speed: float, q: NDArray[np.float64]) -> None:
        S.seq_write(self._target, [(S.T_MODE, mode), (S.T_SPEED, speed), (S.T_Q, q)])

    def _snapshot(self, check: bool = True) -> NDArray[np.float64]:
        if self._proc is None:
            raise DeviceNotConnectedError(self._name, "not connected (call connect())")
        snap = S.seq_read(self._state)
        if not check:
            return snap
        status = int(snap[S.STATUS])
        if status in _ERRORS:
            error, message = _ERRORS[status]
            detail = f"{message}; safety_status_bits={int(snap[S.SAFETY_BITS])}"
            if status in (S.SCRIPT_STOPPED, S.STREAM_TIMEOUT):
                detail += self._pause_note(snap)
            raise error(self._name, detail)
        if not self._proc.is_alive():
            raise DeviceConnectionError(self._name, f"worker process exited (code {self._proc.exitcode})")
        silent = time.monotonic() - snap[S.HEARTBEAT]
        if not self._busy and silent > self._worker_timeout:
            raise DeviceTimeoutError(self._name, f"worker process has not answered for {silent:.1f} s")
        return snap

    def _ring_periods(self, snap: Any) -> NDArray[np.float64]:
        """A copy of the servo loop's recorded periods [s] (the last ``RING`` of them, in ring order)."""
        n = int(min(snap[S.RING_WRITES], S.RING))
        return S.view(self._ring_raw)[:n].copy()

    def _pause_note(self, snap: Any) -> str:
        """Why a watchdog stop or a silent stream may be this computer's doing: the servo loop's longest
        period of its last ``RING`` cycles, when it is longer than the watchdog allows."""
        periods = self._ring_periods(snap)
        if not len(periods):
            return ""
        longest = float(np.max(periods))
        allowed = 1.0 / self._cfg.watchdog_hz
        if longest <= allowed:
            return f"; the servo loop kept time (longest period {longest * 1e3:.0f} ms)"
        return (
            f"; the servo loop itself paused for {longest:.2f} s (the watchdog allows {allowed:.2f} s):"
            " this computer was too busy to command the arm"
        )

    def _receive(self, timeout: float, what: str) -> tuple[Any, ...]:
        assert self._conn is not None and self._proc is not None
        deadline = time.monotonic() + timeout
        while not self._conn.poll(0.05):
            if not self._proc.is_alive():
                raise DeviceConnectionError(self._name, f"worker exited during {what} (code {self._proc.exitcode})")
            if time.monotonic() > deadline:
                raise DeviceTimeoutError(self._name, f"worker did not finish {what} within {timeout:.1f} s")
        try:
            reply: tuple[Any, ...] = self._conn.recv()
        except (EOFError, OSError) as e:
            raise DeviceConnectionError(self._name, f"worker pipe closed during {what}") from e
        return reply

    def _teardown(self, grace: float) -> None:
        """End the worker (after ``grace`` s, then by force) and close the pipe; the watchdog covers a kill."""
        proc, conn = self._proc, self._conn
        self._proc, self._conn = None, None
        if proc is not None:
            proc.join(grace)
            if proc.is_alive():
                proc.terminate()
                proc.join(1.0)
            if proc.is_alive():
                proc.kill()
                proc.join(1.0)
        if conn is not None:
            conn.close()
