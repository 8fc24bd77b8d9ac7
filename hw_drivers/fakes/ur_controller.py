"""A protocol-level fake UR controller (PolyScope 5.11, e-Series) that the real ``ur_rtde`` client talks to.

Three TCP servers on one loopback address, as on a real controller:

* RTDE (30004): ``>HB`` framed messages (size incl. header, type). Recipes are numbered per connection from 1;
  outputs stream at the requested frequency from a thread per connection (ur_rtde gives up after 2.5 s of
  silence). Output types follow ur_rtde's own decode table (``src/robot_state.cpp``), so the byte layout
  matches what the client unpacks.
* dashboard (29999): the line protocol, answering the strings ur_rtde compares against.
* script (30003): accepts the uploaded ``rtde_control`` program and *emulates* it rather than interpreting
  URScript: a 500 Hz controller thread plays the script's main loop on the RTDE registers
  (``input_int_register_0`` = command, ``output_int_register_0`` 1 = ready / 2 = done). The emulated
  command ids are :data:`~hw_drivers.fakes.ur_commands.IMPLEMENTED` (moveJ/moveL and their IK/FK variants,
  speedJ, servoJ, the stops, setTcp and the kinematics getters, computed with :mod:`pilworld.kinematics`
  for the ``ur5e``); any other id stops the program as a URScript runtime error would (``last_error`` says
  which), so the client's call returns False or raises instead of succeeding silently.
  ``timestamp`` is the simulated clock: control cycles x 2 ms.

The arm is the ``side`` arm of a :class:`~hw_drivers.fakes.backend.RigBackend`: ``actual_q``/``actual_qd`` are
read from it and servoJ/moveJ targets written to it. Faults (:class:`~hw_drivers.fakes.faults.FaultSwitch`):

* ``drop`` — output packets are not sent;
* ``corrupt`` — output packets framed correctly but with every payload byte 0xFF (NaN joints, out-of-range
  modes). A broken *frame* (size field below 3) makes ur_rtde 1.6.5 abort the whole client process with an
  uncaught ``std::length_error``, so that is not what this fault sends;
* ``stall`` — no output, no input processing, no dashboard answers; the sockets stay open;
* ``protective_stop`` — latched once seen (the fault is consumed): program stopped, arm held; cleared by
  the dashboard ``unlock protective stop``;
* ``emergency_stop`` — while injected; afterwards the arm is powered off until ``power on`` + ``brake release``;
* ``disconnect`` — all sockets closed, new connections refused while injected.

The ur_rtde constructors hold the GIL, so the client must never run in the process that hosts this fake.
"""

from __future__ import annotations

import contextlib
import select
import socket
import struct
import threading
import time
from dataclasses import dataclass, field
from types import TracebackType

import numpy as np
from numpy.typing import NDArray

from hw_drivers.fakes.backend import RigBackend, check_side
from hw_drivers.fakes.faults import FaultSwitch
from hw_drivers.fakes.ur_commands import IMPLEMENTED, REALTIME, describe
from hw_drivers.fakes.ur_dashboard import DashboardState, status_reply
from hw_drivers.fakes.ur_pose import interpolate, matrix_to_pose, pose_to_matrix, rotvec_to_matrix
from hw_drivers.fakes.ur_protocol import (
    CONTROLLER_VERSION,
    DASHBOARD_PORT,
    FMT,
    IDLE,
    MSG_I,
    MSG_O,
    MSG_P,
    MSG_S,
    MSG_U,
    MSG_V,
    PLAYING,
    POWER_OFF,
    RTDE_PORT,
    RUNNING,
    SAFETY,
    SCRIPT_PORT,
    STOP_CMDS,
    STOPPED,
    TICK_S,
    MSG_v,
    Waypoint,
    frame,
    parse_path,
    register_index,
    type_of,
)
from pilworld.kinematics.fk import fk, fk_flange
from pilworld.kinematics.ik import ik_nearest


@dataclass
class _RtdeSession:
    """One RTDE client's recipes and output schedule."""

    conn: socket.socket
    outputs: list[tuple[str, str]] = field(default_factory=list)
    inputs: dict[int, list[tuple[str, str]]] = field(default_factory=dict)
    period: float = 0.002
    started: bool = False
    next_send: float = 0.0
    buf: bytes = b""


class FakeURController:
    """One fake UR controller on ``host`` (any 127.x.y.z) driving the ``side`` arm of ``backend``."""

    def __init__(
        self, backend: RigBackend, side: str, host: str = "127.0.0.1", faults: FaultSwitch | None = None
    ) -> None:
        self.backend, self.side, self.host = backend, check_side(side), host
        self.faults = faults if faults is not None else FaultSwitch()
        self._lock = threading.RLock()
        self._running = threading.Event()
        self._threads: list[threading.Thread] = []
        self._servers: list[socket.socket] = []
        self._clients: set[socket.socket] = set()
        self.in_int, self.in_double = [0] * 48, [0.0] * 48
        self.out_int, self.out_double = [0] * 48, [0.0] * 48
        self.runtime_state, self.robot_mode, self.safety = STOPPED, RUNNING, "normal"
        self.servoing = False
        self._executing = self._blocking = False
        self._goal: NDArray[np.float64] | None = None  # moveJ goal
        self._speed = 1.0
        self._setpoint = np.zeros(6)
        self._watchdog_s: float | None = None
        self._last_kick = 0.0
        # RTDE connections and how many of their threads hold bytes read but not yet applied: the watchdog
        # counts an input that reached this process, not only one it has got round to (see _kick_overdue)
        self._rtde_conns: set[socket.socket] = set()
        self._rtde_unapplied = 0
        self._program: str | None = None
        self._body = ""  # the uploaded program's text (inside its top-level def)
        self.dh = "ur5e"  # the rig's arms
        self.tcp = np.eye(4)  # T_flange_tcp, set by setTcp (29)
        self.ticks = 0  # control cycles run: the simulated clock (timestamp = ticks * TICK_S)
        self.cycle_gap_max_s = 0.0  # the longest wall time between two control cycles (a loaded machine)
        self._velocity: NDArray[np.float64] | None = None  # speedJ joint velocity, or speedL TCP twist …
        self._cartesian = False  # … when this is set: [vx, vy, vz] m/s, [wx, wy, wz] rad/s in the base frame
        self._line: tuple[NDArray[np.float64], NDArray[np.float64], float, float] | None = None  # moveL
        # ur_rtde re-uploads the script right after stopScript (255) without clearing the register; a real
        # controller has consumed the 255 long before the new program starts, a loaded fake may not have
        self._stale_stop = False
        self._path: list[Waypoint] = []  # the movej/movel lines of the uploaded program (command 45)
        self._queue: list[Waypoint] = []  # waypoints of a running path still to go
        self._path_index = 0
        self._async = False
        self._async_writes = self._async_op = 0
        self.last_error: str | None = None  # why the emulated program stopped, as a runtime error would say

    # -- lifecycle

    def start(self) -> FakeURController:
        self._running.set()
        try:
            for port, serve in ((RTDE_PORT, self._serve_rtde), (DASHBOARD_PORT, self._serve_dashboard)):
                self._listen(port, serve)
            self._listen(SCRIPT_PORT, self._serve_script)
        except OSError:
            self.stop()
            raise
        self._spawn(self._control_loop)
        return self

    def stop(self) -> None:
        self._running.clear()
        with self._lock:
            clients = list(self._clients)
        for c in clients:
            with contextlib.suppress(OSError):
                c.shutdown(socket.SHUT_RDWR)  # wakes a blocked read even while a makefile holds the socket
        for s in [*self._servers, *clients]:
            with contextlib.suppress(OSError):
                s.close()
        for t in self._threads:
            if t is not threading.current_thread():
                t.join(2.0)
        self._servers.clear()
        self._threads.clear()

    def __enter__(self) -> FakeURController:
        return self.start()

    def __exit__(self, t: type[BaseException] | None, e: BaseException | None, tb: TracebackType | None) -> None:
        self.stop()

    @property
    def program_running(self) -> bool:
        return self.runtime_state == PLAYING

    def _spawn(self, fn: object, *args: object) -> None:
        t = threading.Thread(target=fn, args=args, daemon=True, name=f"fake-ur-{self.host}")  # type: ignore[arg-type]
        self._threads.append(t)
        t.start()

    def _listen(self, port: int, serve: object) -> None:
        srv = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
        srv.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        srv.bind((self.host, port))
        srv.listen(8)
        srv.settimeout(0.1)
        self._servers.append(srv)
        self._spawn(self._accept, srv, serve)

    def _accept(self, srv: socket.socket, serve: object) -> None:
        while self._running.is_set():
            try:
                conn, _ = srv.accept()
            except (TimeoutError, OSError):
                continue
            if self.faults.active("disconnect"):
                conn.close()
                continue
            conn.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
            with self._lock:
                self._clients.add(conn)
            self._spawn(self._client, conn, serve)

    def _client(self, conn: socket.socket, serve: object) -> None:
        try:
            serve(conn)  # type: ignore[operator]
        except (OSError, ValueError, struct.error):
            pass  # the peer went away, or a socket closed by stop()/disconnect
        finally:
            with self._lock:
                self._clients.discard(conn)
            conn.close()

    # -- the controller cycle and the emulated rtde_control script

    def _control_loop(self) -> None:
        next_tick = time.monotonic()
        last = next_tick
        while self._running.is_set():
            next_tick += TICK_S
            time.sleep(max(0.0, next_tick - time.monotonic()))
            now = time.monotonic()
            self.cycle_gap_max_s = max(self.cycle_gap_max_s, now - last)  # a pause a real controller never has
            last = now
            if now - next_tick > 0.1:
                next_tick = time.monotonic()  # fell far behind (a loaded machine): do not burst
            if self.faults.active("disconnect"):
                with self._lock:
                    clients = list(self._clients)
                for c in clients:
                    with contextlib.suppress(OSError):
                        c.shutdown(socket.SHUT_RDWR)
            if self.faults.active("stall"):
                continue
            with self._lock:
                self.ticks += 1
                self._safety_tick()
                if self.runtime_state == PLAYING:
                    self._script_tick()

    def _safety_tick(self) -> None:
        if self.faults.active("emergency_stop"):
            if self.safety != "emergency_stop":
                self.safety, self.robot_mode = "emergency_stop", POWER_OFF
                self._halt()
        elif self.safety == "emergency_stop":
            self.safety = "normal"  # released on the robot; still powered off
        if self.faults.active("protective_stop"):
            self.faults.clear("protective_stop")  # latched here; the dashboard unlock clears it
            if self.safety == "normal":
                self.safety = "protective_stop"
                self._halt()
        if self._kick_overdue():
            self._halt()  # rtde_set_watchdog(..., "stop"): no input update in time stops the program

    def _kick_overdue(self) -> bool:
        """No watchdog input for ``1 / watchdog_hz`` s, counting inputs that have reached this process.

        A real controller reads its inputs in hard real time. This fake's threads share one interpreter: after
        the whole process paused (a loaded machine), this thread may run before the RTDE thread has applied
        kicks that arrived on time, and halting then would blame a client that never went silent. So an
        input still waiting in a socket, or read and not yet applied, keeps the program running."""
        if self._watchdog_s is None or time.monotonic() - self._last_kick <= self._watchdog_s:
            return False
        if self._rtde_unapplied:
            return False
        conns = [c for c in self._rtde_conns if c.fileno() >= 0]
        try:
            return not (conns and select.select(conns, [], [], 0)[0])
        except (OSError, ValueError):  # a connection closed under us: nothing is waiting on it
            return True

    def _halt(self) -> None:
        """Stop the program and hold the arm where it is."""
        self.runtime_state, self.servoing, self._blocking, self._goal = STOPPED, False, False, None
        self._velocity, self._line, self._queue = None, None, []
        self._watchdog_s = None
        self._hold()

    def _hold(self) -> None:
        self._setpoint = self.backend.arm_q(self.side)
        self.backend.set_arm_target(self.side, self._setpoint)

    def _step_speed(self, v: NDArray[np.float64]) -> None:
        """One cycle of speedJ (joint velocity) or speedL (TCP twist, joints by IK)."""
        if not self._cartesian:
            self._setpoint = self._setpoint + v * TICK_S
        else:
            T = fk(self._setpoint, self.dh, self.tcp)
            T[:3, 3] += v[:3] * TICK_S
            T[:3, :3] = rotvec_to_matrix(v[3:] * TICK_S) @ T[:3, :3]
            q = ik_nearest(T, self.dh, self._setpoint, self.tcp)
            if q is None:
                self._fail("speedL: the motion leaves the workspace (no inverse kinematics solution)")
                return
            self._setpoint = q
        self.backend.set_arm_target(self.side, self._setpoint)

    def _fail(self, why: str) -> None:
        """A URScript runtime error: the program stops, so the client's call returns False / raises."""
        self.last_error = why
        self._halt()

    def _script_tick(self) -> None:
        if self._velocity is not None:
            self._step_speed(self._velocity)
        if self._line is not None:
            self._step_line()
        if self._goal is not None:
            self._step_move()
        if self._goal is None and self._line is None and self._queue:
            self._next_waypoint()
        if self._async and self._goal is None and self._line is None and not self._queue:
            self._async = False
            self._async_progress(-1)
        if self._blocking:
            return  # a blocking movej/movel: the script does not read commands until it returns
        cmd = self.in_int[0]
        if self._stale_stop:
            if cmd == 255:
                return  # the previous program's stopScript, still in the register: not for this program
            self._stale_stop = False
        if cmd != 0 and cmd not in IMPLEMENTED:
            self._fail(f"{describe(cmd)} is not emulated by the fake controller")
            return
        if cmd in REALTIME:
            self._process(cmd)
            self.out_int[0] = 1
        elif cmd == 0:
            self._executing = False
            self.out_int[0] = 1
        elif not self._executing:
            self._executing = True
            self._process(cmd)
            if cmd != 255 and not self._blocking:
                self.out_int[0] = 2

    def _process(self, cmd: int) -> None:
        try:
            self._process_cmd(cmd)
        except ValueError as e:  # bad arguments (NaN pose, no IK solution): URScript raises, the program stops
            self._fail(f"{describe(cmd)}: {e}")

    def _ik(self, pose: NDArray[np.float64], seed: NDArray[np.float64]) -> NDArray[np.float64]:
        q = ik_nearest(pose_to_matrix(pose), self.dh, seed, self.tcp)
        if q is None:
            raise ValueError(f"no inverse kinematics solution for pose {np.round(pose, 4).tolist()}")
        return q

    def _start_movej(self, q: NDArray[np.float64], speed: float, blocking: bool) -> None:
        self.servoing, self._goal, self._velocity, self._line = False, q, None, None
        self._speed = max(1e-3, speed)
        self._setpoint = self.backend.arm_q(self.side)
        self._blocking = blocking
        if not blocking:
            self._async = True
            self._async_progress(0)

    def _start_movel(self, goal: NDArray[np.float64], speed: float) -> None:
        """A straight TCP line from where the arm is to ``goal`` (4x4) at ``speed`` [m/s]."""
        self._setpoint = self.backend.arm_q(self.side)
        self._line = (fk(self._setpoint, self.dh, self.tcp), goal, max(1e-4, speed), 0.0)

    def _async_progress(self, value: int) -> None:
        """write_async_progress_register(): op id bits 24-30, write count 16-23, bit 15 running, progress 0-14."""
        self._async_writes = (self._async_writes + 1) % 128
        if value == 0:
            self._async_op = (self._async_op + 1) % 128
        reg = self._async_writes * 65536 + self._async_op * 16777216
        self.out_int[2] = reg + min(value, 32767) + 32768 if value >= 0 else reg

    def _next_waypoint(self) -> None:
        move, is_pose, target, speed = self._queue.pop(0)
        if self._async:
            self._async_progress(self._path_index)
        self._path_index += 1
        if move == "movej":
            q = self._ik(target, self._setpoint) if is_pose else target
            self._goal, self._speed = q, max(1e-3, speed)
            self._setpoint = self.backend.arm_q(self.side)
        else:
            self._start_movel(pose_to_matrix(target) if is_pose else fk(target, self.dh, self.tcp), speed)

    def _process_cmd(self, cmd: int) -> None:
        q = np.array(self.in_double[:6])
        blocking = self.in_int[1] == 0
        if cmd in (29, 40, 43, 44, 46, 30, 58):
            self._query(cmd, q)
        elif cmd == 2:  # moveJ_IK(pose, speed, acceleration, async)
            self._start_movej(self._ik(q, self._setpoint), self.in_double[6], blocking)
        elif cmd in (3, 4):  # moveL(pose, …) / moveL_FK(q, …): a straight TCP line, joints through IK
            goal = pose_to_matrix(q) if cmd == 3 else fk(q, self.dh, self.tcp)
            self._start_movej(self.backend.arm_q(self.side), self.in_double[6], blocking)
            self._goal = None
            self._start_movel(goal, self.in_double[6])
        elif cmd == 45:  # moveJ/moveL(path): the waypoints were injected into the re-uploaded program
            if not self._path:
                raise ValueError("the uploaded program has no movej/movel path")
            self._start_movej(self.backend.arm_q(self.side), 1.0, blocking)
            self._goal, self._queue, self._path_index = None, list(self._path), 0
        elif cmd in (9, 10):  # speedJ(qd, …) / speedL(xd, …): a velocity until speedStop / another command
            self.servoing, self._goal, self._line, self._queue = False, None, None, []
            self._velocity, self._cartesian = q, cmd == 10
        elif cmd == 24:  # servoL(pose, …): servoJ to the IK solution nearest the setpoint (real-time)
            self.servoing, self._goal, self._velocity, self._line, self._queue = True, None, None, None, []
            self._setpoint = self._ik(q, self._setpoint)
            self.backend.set_arm_target(self.side, self._setpoint)
        elif cmd == 47:  # isSteady → output_int_register_1
            moving = self._goal is not None or self._line is not None or self._velocity is not None or self._queue
            still = float(np.max(np.abs(self.backend.arm_qd(self.side)))) < 1e-4
            self.out_int[1] = int(still and not moving)
        elif cmd in (60, 61):  # getInverseKinematicsHasSolution(x[, qnear, …]) → output_int_register_1
            seed = self.backend.arm_q(self.side) if cmd == 60 else np.array(self.in_double[6:12])
            self.out_int[1] = int(ik_nearest(pose_to_matrix(q), self.dh, seed, self.tcp) is not None)
        elif cmd == 11:  # servoJ: the servo thread tracks the latest target
            self.servoing, self._goal, self._velocity, self._line, self._queue = True, None, None, None, []
            self._setpoint = q
            self.backend.set_arm_target(self.side, q)
        elif cmd == 1:  # moveJ(q, speed, acceleration, async)
            self._start_movej(q, self.in_double[6], blocking)
        elif cmd in STOP_CMDS:
            self.servoing, self._goal, self._velocity, self._line, self._queue = False, None, None, None, []
            if self._async:
                self._async = False
                self._async_progress(-1)
            self._hold()
        elif cmd == 35:  # setWatchdog(min_frequency)
            self._watchdog_s = 1.0 / max(1e-3, self.in_double[0])
            self._last_kick = time.monotonic()
        elif cmd == 31:  # triggerProtectiveStop
            self.safety = "protective_stop"
            self._halt()
        elif cmd == 255:  # stopScript
            self._halt()

    def _query(self, cmd: int, arg: NDArray[np.float64]) -> None:
        """setTcp and the kinematics getters; results go to output_double_register_0…5."""
        d = np.array(self.in_double[:14])
        if cmd == 29:  # setTcp(pose)
            self.tcp = pose_to_matrix(arg)
            return
        if cmd == 40:  # getTCPOffset
            result = matrix_to_pose(self.tcp)
        elif cmd == 43:  # getForwardKinematics(): the current joints with the active TCP
            result = matrix_to_pose(fk(self.backend.arm_q(self.side), self.dh, self.tcp))
        elif cmd == 44:  # getForwardKinematics(q, tcp_offset)
            result = matrix_to_pose(fk(arg, self.dh, pose_to_matrix(d[6:12])))
        elif cmd == 46:  # getInverseKinematics(x): the solution nearest the current joints
            result = self._ik(arg, self.backend.arm_q(self.side))
        elif cmd == 30:  # getInverseKinematics(x, qnear, max errors): nearest to qnear
            result = self._ik(arg, d[6:12])
        else:  # 58 getActualToolFlangePose
            result = matrix_to_pose(fk_flange(self.backend.arm_q(self.side), self.dh))
        self.out_double[:6] = [float(v) for v in result]

    def _step_line(self) -> None:
        """One cycle of moveL: advance along the straight line at the commanded speed [m/s], joints by IK."""
        assert self._line is not None
        start, goal, speed, s = self._line
        length = float(np.linalg.norm(goal[:3, 3] - start[:3, 3]))
        s = 1.0 if length < 1e-9 else min(1.0, s + speed * TICK_S / length)
        q = ik_nearest(interpolate(start, goal, s), self.dh, self._setpoint, self.tcp)
        if q is None:
            self._fail("moveL: the straight line leaves the workspace (no inverse kinematics solution)")
            return
        self._setpoint = q
        self.backend.set_arm_target(self.side, q)
        self._line = None if s >= 1.0 else (start, goal, speed, s)
        if self._line is None:
            self._goal = q  # settle: done once the arm has reached the last point
            self._speed = np.inf

    def _step_move(self) -> None:
        assert self._goal is not None
        delta = self._goal - self._setpoint
        step = self._speed * TICK_S
        largest = float(np.max(np.abs(delta)))
        self._setpoint = self._goal.copy() if largest <= step else self._setpoint + delta * (step / largest)
        self.backend.set_arm_target(self.side, self._setpoint)
        if largest <= step and np.max(np.abs(self.backend.arm_q(self.side) - self._goal)) < 1e-3:
            self._goal = None
            if self._blocking and not self._queue:
                self._blocking = False
                self.out_int[0] = 2

    def _start_program(self, name: str, body: str = "") -> None:
        with self._lock:
            if name != "rtde_control" or self.safety != "normal" or self.robot_mode != RUNNING:
                return  # only ur_rtde's control script is emulated; a stopped robot cannot run programs
            self._program, self._body = name, body
            self._path = parse_path(body)
            self.runtime_state = PLAYING
            self._executing = self._blocking = self.servoing = False
            self._goal, self._watchdog_s = None, None
            self._velocity, self._line, self.last_error, self._queue = None, None, None, []
            self._async = False
            self._async_progress(-1)  # reset_async_progress()
            self._stale_stop = self.in_int[0] == 255
            self.tcp = np.eye(4)  # the uploaded script starts with the installation's TCP (the flange here)
            self._hold()
            self.out_int[0] = 1  # signal_ready()

    # -- RTDE

    def _serve_rtde(self, conn: socket.socket) -> None:
        session = _RtdeSession(conn)
        with self._lock:
            self._rtde_conns.add(conn)
        try:
            while self._running.is_set():
                self._rtde_cycle(session)
        finally:
            with self._lock:
                self._rtde_conns.discard(conn)

    def _rtde_cycle(self, rs: _RtdeSession) -> None:
        """Read and apply what arrives until the next output packet is due, then send it."""
        wait = max(0.0, rs.next_send - time.monotonic()) if rs.started else 0.1
        if select.select([rs.conn], [], [], wait)[0]:
            with self._lock:
                self._rtde_unapplied += 1  # from here until applied, a kick is on its way (_kick_overdue)
            try:
                data = rs.conn.recv(65536)
                if not data:
                    raise ConnectionResetError("the RTDE client closed the connection")
                rs.buf += data
                while len(rs.buf) >= 3:
                    size, kind = struct.unpack_from(">HB", rs.buf)
                    if len(rs.buf) < size:
                        break
                    payload, rs.buf = rs.buf[3:size], rs.buf[size:]
                    if not self.faults.active("stall"):
                        self._rtde_message(rs, kind, payload)
            finally:
                with self._lock:
                    self._rtde_unapplied -= 1
        if rs.started and time.monotonic() >= rs.next_send:
            rs.next_send = max(rs.next_send + rs.period, time.monotonic() - rs.period)
            if self.faults.active("stall") or self.faults.active("drop"):
                return
            packet = self._output_packet(rs.outputs)
            if self.faults.active("corrupt"):  # intact frame, garbled content (NaN doubles, huge ints)
                packet = packet[:4] + b"\xff" * (len(packet) - 4)
            rs.conn.sendall(packet)

    def _rtde_message(self, rs: _RtdeSession, kind: int, payload: bytes) -> None:
        conn = rs.conn
        if kind == MSG_U:
            self._on_input(payload, rs.inputs)
        elif kind == MSG_O:
            rs.period = 1.0 / max(1.0, struct.unpack_from(">d", payload)[0])
            names = [n for n in payload[8:].decode().split(",") if n]
            rs.outputs = [(n, type_of(n, "output")) for n in names]
            ok = all(t != "NOT_FOUND" for _, t in rs.outputs)
            conn.sendall(frame(MSG_O, bytes([1 if ok else 0]) + ",".join(t for _, t in rs.outputs).encode()))
        elif kind == MSG_I:
            names = [n for n in payload.decode().split(",") if n]
            types = [(n, type_of(n, "input")) for n in names]
            rid = len(rs.inputs) + 1 if all(t != "NOT_FOUND" for _, t in types) else 0
            if rid:
                rs.inputs[rid] = types
            conn.sendall(frame(MSG_I, bytes([rid]) + ",".join(t for _, t in types).encode()))
        elif kind in (MSG_S, MSG_P):
            rs.started = kind == MSG_S and bool(rs.outputs)
            rs.next_send = time.monotonic()
            conn.sendall(frame(kind, b"\x01"))
        elif kind == MSG_V:
            conn.sendall(frame(MSG_V, b"\x01"))
        elif kind == MSG_v:
            conn.sendall(frame(MSG_v, struct.pack(">IIII", *CONTROLLER_VERSION)))

    def _on_input(self, payload: bytes, inputs: dict[int, list[tuple[str, str]]]) -> None:
        recipe = inputs.get(payload[0])
        if recipe is None:
            return
        values = struct.unpack_from(">" + "".join(FMT[t] for _, t in recipe), payload, 1)
        with self._lock:
            i = 0
            for name, rtde_type in recipe:
                n = int(FMT[rtde_type][0]) if FMT[rtde_type][0].isdigit() else 1
                if (reg := register_index(name, "input_int_register_")) is not None:
                    self.in_int[reg] = int(values[i])
                    if reg == 0:
                        self._last_kick = time.monotonic()
                elif (reg := register_index(name, "input_double_register_")) is not None:
                    self.in_double[reg] = float(values[i])
                i += n

    def _output_packet(self, outputs: list[tuple[str, str]]) -> bytes:
        q, qd = self.backend.arm_q(self.side), self.backend.arm_qd(self.side)
        with self._lock:
            safety_mode, safety_bits, _ = SAFETY[self.safety]
            powered = self.robot_mode in (IDLE, RUNNING)
            scalars: dict[str, float | int] = {
                "timestamp": self.ticks * TICK_S,  # the simulated clock: frozen while stalled
                "robot_mode": self.robot_mode,
                "safety_mode": safety_mode,
                "safety_status_bits": safety_bits,
                "runtime_state": self.runtime_state,
                "robot_status_bits": int(powered) | (int(self.runtime_state == PLAYING) << 1),
                "speed_scaling": 1.0,
                "target_speed_fraction": 1.0,
            }
            target = self._setpoint.copy()
            tcp = self.tcp.copy()
            flat: list[float | int] = []
            for name, rtde_type in outputs:
                if name == "actual_q":
                    flat.extend(q.tolist())
                elif name == "target_q":
                    flat.extend(target.tolist())
                elif name in ("actual_TCP_pose", "target_TCP_pose"):
                    flat.extend(matrix_to_pose(fk(q if name[0] == "a" else target, self.dh, tcp)).tolist())
                elif name in ("actual_qd", "target_qd"):
                    flat.extend(qd.tolist())
                elif name == "joint_mode":
                    flat.extend([253] * 6)  # JOINT_RUNNING_MODE
                elif (reg := register_index(name, "output_int_register_")) is not None:
                    flat.append(self.out_int[reg])
                elif (reg := register_index(name, "output_double_register_")) is not None:
                    flat.append(self.out_double[reg])
                else:
                    fmt = FMT[rtde_type]
                    count = int(fmt[0]) if fmt[0].isdigit() else 1
                    flat.extend([scalars.get(name, 0)] * count)
        fmt = ">B" + "".join(FMT[t] for _, t in outputs)
        return frame(MSG_U, struct.pack(fmt, 1, *flat))

    # -- dashboard

    def _serve_dashboard(self, conn: socket.socket) -> None:
        conn.sendall(b"Connected: Universal Robots Dashboard Server\n")
        reader = conn.makefile("rb")
        for raw in reader:
            if not self._running.is_set():
                return
            if self.faults.active("stall"):
                continue
            line = raw.decode(errors="replace").strip()
            reply = self._dashboard(line)
            conn.sendall((reply + "\n").encode())
            if line == "quit":
                return

    def _dashboard(self, line: str) -> str:
        cmd = line.lower()
        with self._lock:
            program = self._program or "<unnamed>"
            if cmd == "stop":
                self._halt()
                return "Stopped"
            if cmd == "play":
                if self._program is None:
                    return "Failed to execute: play"
                self._start_program(self._program, self._body)
                return "Starting program" if self.runtime_state == PLAYING else "Failed to execute: play"
            if cmd == "pause":
                self._halt()
                return "Pausing program"
            if cmd == "unlock protective stop":
                if self.safety != "protective_stop":
                    return "Cannot unlock protective stop: the robot is not in a protective stop"
                self.safety = "normal"
                return "Protective stop releasing"
            if cmd in ("power on", "power off", "brake release"):
                if self.safety == "emergency_stop":
                    return f"Cannot {cmd}: emergency stop active"
                self.robot_mode = {"power on": IDLE, "power off": POWER_OFF, "brake release": RUNNING}[cmd]
                return {"power on": "Powering on", "power off": "Powering off", "brake release": "Brake releasing"}[cmd]
            state = DashboardState(self.robot_mode, self.safety, self.runtime_state == PLAYING, program)
        return status_reply(line, state)

    # -- primary/secondary script interface

    def _serve_script(self, conn: socket.socket) -> None:
        """Collect top-level ``def name(): … end`` programs; a complete one starts (and replaces) the program."""
        pending = b""
        name: str | None = None
        body: list[str] = []
        while self._running.is_set():
            if not select.select([conn], [], [], 0.1)[0]:
                continue
            data = conn.recv(65536)
            if not data:
                return
            pending += data
            *lines, pending = pending.split(b"\n")
            for raw in lines:
                line = raw.decode(errors="replace").rstrip()
                if line.startswith("def ") and line.endswith("():"):
                    name, body = line[4:-3].strip(), []
                elif line == "end" and name is not None:
                    self._start_program(name, "\n".join(body))
                    name = None
                elif name is not None:
                    body.append(line)
