"""The process that owns one arm's ur_rtde interfaces and runs its servoJ loop.

Why a process: the ur_rtde constructors (and some calls) hold Python's GIL while they block on the network,
so one arm connecting would freeze every other thread of the robot. Here nothing else shares the GIL.

The loop (``servo_rate_hz``, timed by ``rtde_c.initPeriod()/waitPeriod()``) reads the latest RTDE sample,
publishes it to shared memory, moves a setpoint toward the parent's target along a straight line in joint
space at a capped speed, and sends it with servoJ. The controller watchdog is always armed
(``setWatchdog``): servoJ writes ``input_int_register_0`` every cycle, so if this process dies or stops
commanding, the controller stops the program within ``1 / watchdog_hz`` s.

On any fault (safety stop, script stopped, silent or lost stream, implausible data) the loop stops sending,
holds the setpoint at the last measured position (so a recovery never jumps) and publishes a status code;
it never calls a blocking ur_rtde command on a dead stream (those wait for a reply for up to 300 s), the
watchdog stops the arm instead.
"""

from __future__ import annotations

import importlib
import os
import time
from multiprocessing.connection import Connection
from typing import Any

import numpy as np

from hw_drivers.ur import shared as S

RECEIVE_VARIABLES = [
    "timestamp",
    "actual_q",
    "actual_qd",
    "robot_mode",
    "safety_mode",
    "safety_status_bits",
    "runtime_state",
]
MAX_ABS_Q = 2 * np.pi + 0.2  # UR joints turn ±360°; beyond that a reading is corrupt


class WorkerError(Exception):
    """A failure the parent turns into a typed error: ``kind`` is a status code of :mod:`shared`."""

    def __init__(self, kind: int, message: str) -> None:
        super().__init__(message)
        self.kind = kind


def _connect(cfg: S.WorkerConfig) -> tuple[Any, Any, Any]:
    rtde_control = importlib.import_module("rtde_control")
    rtde_receive = importlib.import_module("rtde_receive")
    dashboard_client = importlib.import_module("dashboard_client")
    last = ""
    for attempt in range(cfg.attempts):
        if attempt:
            time.sleep(cfg.retry_delay)
        made: list[Any] = []
        try:
            db = dashboard_client.DashboardClient(cfg.host)
            db.connect()
            made.append(db)
            rtde_c = rtde_control.RTDEControlInterface(cfg.host, cfg.servo_rate_hz)
            made.append(rtde_c)
            rtde_r = rtde_receive.RTDEReceiveInterface(cfg.host, cfg.servo_rate_hz, RECEIVE_VARIABLES)
            return db, rtde_c, rtde_r
        except Exception as e:  # ur_rtde raises RuntimeError for everything (refused, timeout, no script)
            last = f"{type(e).__name__}: {e}"
            for iface in reversed(made):
                _quiet(iface.disconnect)
    raise WorkerError(S.CONNECTION_LOST, f"could not connect to {cfg.host} after {cfg.attempts} attempts ({last})")


def _quiet(fn: Any, *args: Any) -> Any:
    try:
        return fn(*args)
    except Exception:
        return None


class ServoLoop:
    def __init__(self, cfg: S.WorkerConfig, conn: Connection, state: Any, target: Any, ring: Any) -> None:
        self.cfg, self.conn = cfg, conn
        self.state, self.target, self.ring = S.view(state), S.view(target), S.view(ring)
        self.db, self.rtde_c, self.rtde_r = _connect(cfg)
        self.dt = 1.0 / cfg.servo_rate_hz
        self.status = S.STARTING
        self.q = np.array(self.rtde_r.getActualQ(), dtype=np.float64)
        self.qd = np.zeros(6)
        self.setpoint = self.q.copy()
        self.target_seq, self.stats_reset = -1.0, self.target[S.T_STATS_RESET]
        self.last_ts, self.t_fresh = -1.0, time.monotonic()
        self.bits, self.runtime, self.mode = 0, 0, 0
        self.goal, self.speed = self.q.copy(), cfg.max_joint_speed
        self.cycles, self.missed, self.ring_writes = 0, 0, 0
        self.stats_t0 = time.monotonic()
        self._arm()

    def _arm(self) -> None:
        """Watchdog on, setpoint at the measured position, targets reset to hold: the state after (re)start."""
        self.status = S.STARTING
        self._read(force=True)
        if self.status != S.STARTING:
            raise WorkerError(self.status, "implausible RTDE data at start")
        if not self.rtde_c.setWatchdog(self.cfg.watchdog_hz):
            raise WorkerError(S.SCRIPT_STOPPED, "the control script did not accept setWatchdog")
        self.setpoint, self.goal = self.q.copy(), self.q.copy()
        self.target_seq = self.target[S.T_SEQ]  # targets sent before now are stale: hold
        self.status = S.OK
        self._publish(time.monotonic())  # before replying: the parent reads this state right away

    # -- one cycle

    def run(self) -> None:
        last_start = time.monotonic()
        while True:
            t0 = self.rtde_c.initPeriod()
            now = time.monotonic()
            self._count(now - last_start)
            last_start = now
            self._read()
            self._check(now)
            if self.conn.poll() and not self._command():
                return
            self._follow_target()
            if self.status == S.OK:
                self._servo()
            self._publish(now)
            self.rtde_c.waitPeriod(t0)

    def _read(self, force: bool = False) -> None:
        r = self.rtde_r
        try:
            ts = r.getTimestamp()
            if ts == self.last_ts and not force:
                return
            q = np.array(r.getActualQ(), dtype=np.float64)
            qd = np.array(r.getActualQd(), dtype=np.float64)
            bits, runtime, mode = r.getSafetyStatusBits(), r.getRuntimeState(), r.getRobotMode()
        except Exception:  # ur_rtde lost its connection under us
            self._fail(S.CONNECTION_LOST)
            return
        bad = ""
        if q.shape != (6,) or not np.all(np.isfinite(q)) or np.max(np.abs(q)) > MAX_ABS_Q:
            bad = f"actual_q {q.tolist()}"
        elif not np.all(np.isfinite(qd)):
            bad = f"actual_qd {qd.tolist()}"
        elif not 0 <= runtime <= 5 or not -1 <= mode <= 8 or bits >= 1 << 11:
            bad = f"runtime_state {runtime}, robot_mode {mode}, safety_status_bits {bits}"
        elif ts < self.last_ts:
            bad = f"controller timestamp went back from {self.last_ts} to {ts}"
        if bad:
            self._fail(S.PROTOCOL_ERROR)
            return
        self.q, self.qd, self.bits, self.runtime, self.mode = q, qd, int(bits), int(runtime), int(mode)
        self.last_ts, self.t_fresh = ts, time.monotonic()

    def _check(self, now: float) -> None:
        if self.status != S.OK:
            return
        if now - self.t_fresh > self.cfg.stream_timeout:
            connected = bool(self.rtde_r.isConnected()) and bool(self.rtde_c.isConnected())
            self._fail(S.STREAM_TIMEOUT if connected else S.CONNECTION_LOST)
        elif self.bits & S.EMERGENCY_MASK:
            self._fail(S.EMERGENCY_STOP)
        elif self.bits & S.PROTECTIVE_MASK:
            self._fail(S.PROTECTIVE_STOP)
        elif self.bits & S.OTHER_STOP_MASK:
            self._fail(S.SAFETY_STOP)
        elif self.runtime != S.PLAYING:
            self._fail(S.SCRIPT_STOPPED)

    def _fail(self, status: int) -> None:
        """Stop commanding; the controller's watchdog halts the program. Hold where the arm is."""
        if self.status in (S.OK, S.STARTING):
            self.status = status
            self.setpoint, self.goal = self.q.copy(), self.q.copy()

    def _follow_target(self) -> None:
        seq = self.target[S.T_SEQ]
        if seq != self.target_seq and seq % 2 == 0:
            snap = S.seq_read(self.target)
            self.target_seq = snap[S.T_SEQ]
            if self.status == S.OK:
                hold = snap[S.T_MODE] == S.HOLD
                self.goal = self.setpoint.copy() if hold else snap[S.T_Q].copy()
                self.speed = min(float(snap[S.T_SPEED]), self.cfg.max_joint_speed)
        if self.target[S.T_STATS_RESET] != self.stats_reset:
            self.stats_reset = self.target[S.T_STATS_RESET]
            self.cycles, self.missed, self.ring_writes, self.stats_t0 = 0, 0, 0, time.monotonic()

    def _servo(self) -> None:
        delta = self.goal - self.setpoint
        largest = float(np.max(np.abs(delta)))
        step = self.speed * self.dt  # nominal period: a late cycle moves less, never faster
        self.setpoint = self.goal.copy() if largest <= step else self.setpoint + delta * (step / largest)
        c = self.cfg
        try:
            self.rtde_c.servoJ(self.setpoint.tolist(), 0.0, 0.0, self.dt, c.lookahead_time, c.gain)
        except Exception:
            self._fail(S.CONNECTION_LOST)

    def _count(self, period: float) -> None:
        if self.cycles:
            self.ring[self.ring_writes % S.RING] = period
            self.ring_writes += 1
            self.missed += period > 1.5 * self.dt
        self.cycles += 1

    def _publish(self, now: float) -> None:
        S.seq_write(
            self.state,
            [
                (S.T_FRESH, self.t_fresh),
                (S.Q, self.q),
                (S.QD, self.qd),
                (S.SAFETY_BITS, self.bits),
                (S.RUNTIME_STATE, self.runtime),
                (S.ROBOT_MODE, self.mode),
                (S.STATUS, self.status),
                (S.HEARTBEAT, now),
                (S.CYCLES, self.cycles),
                (S.STATS_T0, self.stats_t0),
                (S.MISSED, self.missed),
                (S.RING_WRITES, self.ring_writes),
                (S.SETPOINT, self.setpoint),
            ],
        )

    # -- commands from the parent (blocking; the parent waits for the reply)

    def _command(self) -> bool:
        """Serve one request; False when the loop should end."""
        try:
            request = self.conn.recv()
        except (EOFError, OSError):
            request = ("disconnect",)  # the parent died: stop the arm and leave
        try:
            if request[0] == "recover":
                self._recover()
            elif request[0] == "disconnect":
                self._close()
                _quiet(self.conn.send, ("ok", ""))
                return False
            _quiet(self.conn.send, ("ok", ""))
        except WorkerError as e:
            _quiet(self.conn.send, ("error", e.kind, str(e)))
        except Exception as e:
            _quiet(self.conn.send, ("error", S.PROTOCOL_ERROR, f"{type(e).__name__}: {e}"))
        return True

    def _wait(self, what: str, cond: Any, timeout: float, poll: float = 0.01) -> None:
        deadline = time.monotonic() + timeout
        while True:
            self._read()
            if cond():
                return
            if time.monotonic() > deadline:
                raise WorkerError(S.SCRIPT_STOPPED, f"could not {what} within {timeout} s")
            time.sleep(poll)

    def _recover(self) -> None:
        since = self.last_ts  # decide on a sample taken after the request, not on one already seen
        self._wait("get a fresh RTDE sample", lambda: self.last_ts != since, 1.0)
        if self.bits & S.EMERGENCY_MASK:
            raise WorkerError(S.EMERGENCY_STOP, "emergency stop engaged: release it on the robot, then recover()")
        self._publish_status(S.STARTING)
        _quiet(self.db.closeSafetyPopup)
        _quiet(self.db.closePopup)
        if self.bits & S.PROTECTIVE_MASK:
            # PolyScope refuses the unlock for 5 s after the stop: keep asking.
            self._wait("unlock the protective stop", lambda: _unlock(self.db), 8.0, poll=0.25)
            self._wait("leave the protective stop", lambda: not self.bits & S.PROTECTIVE_MASK, 2.0)
        if self.mode != S.ROBOT_RUNNING:  # powered off after a released emergency stop
            _quiet(self.db.powerOn)
            _quiet(self.db.brakeRelease)
            self._wait("power on and release the brakes", lambda: self.mode == S.ROBOT_RUNNING, 15.0)
        self.rtde_c.reuploadScript()
        self._wait("restart the control script", lambda: self.runtime == S.PLAYING, 5.0)
        self._arm()

    def _publish_status(self, status: int) -> None:
        self.status = status
        self._publish(time.monotonic())

    def _close(self) -> None:
        """Leave the arm stopped: servoStop and stopScript over a live stream, else rely on the watchdog.

        The sockets are left to the process exit (``main`` ends with ``os._exit``): ur_rtde's disconnect()
        sleeps 0.5 s per interface and joins threads that can hang on a dead link.
        """
        if self.status == S.OK and time.monotonic() - self.t_fresh < self.cfg.stream_timeout:
            _quiet(self.rtde_c.servoStop, 2.0)
            _quiet(self.rtde_c.stopScript)
        self.status = S.CLOSED
        self._publish(time.monotonic())


def _unlock(db: Any) -> bool:
    try:
        db.unlockProtectiveStop()
        return True
    except Exception:
        return False


def main(conn: Connection, state: Any, target: Any, ring: Any, cfg: S.WorkerConfig) -> None:
    """Entry point of the worker process: connect, report, servo until told to disconnect."""
    try:
        loop = ServoLoop(cfg, conn, state, target, ring)
    except WorkerError as e:
        _quiet(conn.send, ("error", e.kind, str(e)))
        return
    except Exception as e:
        _quiet(conn.send, ("error", S.CONNECTION_LOST, f"{type(e).__name__}: {e}"))
        return
    loop._publish(time.monotonic())
    conn.send(("ok", ""))
    loop.run()
    conn.close()
    os._exit(0)  # skip ur_rtde's destructors (each disconnect() sleeps, and may hang on a dead link)
