"""The fake rig: every protocol fake of a rig file's ``hardware.fake`` section, in one child process.

One MuJoCo scene (:class:`~hw_drivers.fakes.backend.SimBackend`) sits behind two fake UR controllers
(RTDE 30004, dashboard 29999, script 30003 on two loopback addresses), a fake Dynamixel bus and a
fake Robotiq gripper on pseudo-terminals, and an MJPEG camera server — whichever drivers the rig
file names. The real client libraries then talk to them from the parent process exactly as to a
real rig.

Why a separate process: ``ur_rtde``'s constructors hold the GIL while they wait for the controller,
so a fake controller in the same process as the client deadlocks; and the 500 Hz servo traffic
should not compete with the caller's threads for the GIL either.

The parent keeps a pipe to the child for what a person would do at a real rig — set up a subtask's
scene (:meth:`FakeRig.reset`), look at the result (:meth:`FakeRig.check`, :meth:`FakeRig.object_poses`
— privileged, for tests and the simulator's checker) — and for fault injection (:meth:`FakeRig.inject`).
"""

from __future__ import annotations

import multiprocessing as mp
import traceback
from dataclasses import dataclass, field
from multiprocessing.connection import Connection
from pathlib import Path
from typing import Any

from hw_drivers.errors import DeviceConnectionError, DeviceTimeoutError

DEVICES = ("left_arm", "right_arm", "left_gripper", "right_gripper", "cameras")


@dataclass(frozen=True)
class FakeEndpoints:
    """Where the drivers find the fakes."""

    arm_hosts: dict[str, str]  # side -> loopback address of its fake UR controller
    gripper_ports: dict[str, str]  # side -> pseudo-terminal path
    camera_urls: dict[str, str]  # camera -> MJPEG stream URL
    extra: dict[str, Any] = field(default_factory=dict)


class FakeRigError(DeviceConnectionError):
    """The fake rig's process failed (its traceback is in the message)."""


# ---------------------------------------------------------------------------------------------- child


def _serve(conn: Connection, rig_path: str, seed: int, subtask: int) -> None:
    """The child process: start the backend and the fakes, send the endpoints, then serve requests."""
    from hw_drivers.fakes.backend import SimBackend
    from hw_drivers.fakes.faults import FaultSwitch
    from pilworld.config.rig import RigConfig

    started: list[Any] = []
    backend: SimBackend | None = None
    try:
        rig = RigConfig.load(rig_path)
        assert rig.hardware is not None and rig.hardware.fake is not None
        hw, fake = rig.hardware, rig.hardware.fake
        sizes = {name: (size.width, size.height) for name, size in fake.stream_sizes.items()}
        backend = SimBackend(rig, fake.task, seed=seed, subtask=subtask, camera_fps=fake.camera_fps, stream_sizes=sizes)
        faults = {d: FaultSwitch(seed=i) for i, d in enumerate(DEVICES)}
        arm_hosts: dict[str, str] = {}
        gripper_ports: dict[str, str] = {}
        from hw_drivers.fakes.ur_controller import FakeURController

        controllers: dict[str, FakeURController] = {}

        for side, host in (("left", fake.left_host), ("right", fake.right_host)):
            ctrl = FakeURController(backend, side, host=host, faults=faults[f"{side}_arm"])
            ctrl.start()
            started.append(ctrl)
            controllers[side] = ctrl
            arm_hosts[side] = host
        for side in ("left", "right"):
            g = getattr(hw.grippers, side)
            if g.driver == "dynamixel":
                from hw_drivers.fakes.dynamixel_bus import FakeDynamixelBus

                bus = FakeDynamixelBus(
                    backend,
                    {g.servo_id: side},
                    faults=faults[f"{side}_gripper"],
                    ticks_closed=g.ticks_closed,
                    ticks_open=g.ticks_open,
                )
                bus.start()
                started.append(bus)
                gripper_ports[side] = bus.path
            else:
                from hw_drivers.fakes.robotiq import FakeRobotiqGripper

                rq = FakeRobotiqGripper(backend, side, slave_id=g.slave_id, faults=faults[f"{side}_gripper"])
                rq.start()
                started.append(rq)
                gripper_ports[side] = rq.path
        from hw_drivers.fakes.mjpeg_camera import MJPEGCameraServer

        server = MJPEGCameraServer(backend, fps=fake.camera_fps, faults=faults["cameras"])
        server.start()
        started.append(server)
        camera_urls = {cam: server.url(cam) for cam in backend.cameras}
        conn.send(("ok", FakeEndpoints(arm_hosts, gripper_ports, camera_urls)))
    except BaseException:
        conn.send(("error", traceback.format_exc()))
        for part in reversed(started):
            part.stop()
        if backend is not None:
            backend.close()
        return

    person: dict[str, Any] = {"rig": rig}  # the calibration person's state (hw_drivers.fakes.calibration_person)
    try:
        while True:
            try:
                op, kwargs = conn.recv()
            except EOFError:  # the parent went away: stop everything
                break
            if op == "stop":
                conn.send(("ok", None))
                break
            try:
                if op == "timing":
                    gap = max((c.cycle_gap_max_s for c in controllers.values()), default=0.0)
                    conn.send(("ok", {**backend.timing(), "controller_gap_max_s": gap}))
                    continue
                result = _handle(backend, faults, op, kwargs, person)
                if op == "reset":  # a new subtask: the timing record starts afresh (backend.timing() does too)
                    for c in controllers.values():
                        c.cycle_gap_max_s = 0.0
                conn.send(("ok", result))
            except BaseException:
                conn.send(("error", traceback.format_exc()))
    finally:
        if person.get("presenter") is not None:
            person["presenter"].stop()
        for part in reversed(started):
            try:
                part.stop()
            except Exception:  # stopping the others matters more than reporting this one
                traceback.print_exc()
        backend.close()


def _handle(backend: Any, faults: dict[str, Any], op: str, kw: dict[str, Any], person: dict[str, Any]) -> Any:
    if op in ("board", "present", "presented"):
        return _person(backend, op, kw, person)
    if op == "reset":
        task, seed, subtask = kw["task"], kw["seed"], kw["subtask"]

        def reset(robot: Any) -> dict[str, Any]:
            start = robot.reset(seed=seed, subtask=subtask, task=task, history=0)
            return {"state": start.observation.state.tolist(), "instruction": robot.subtask.instruction}

        return backend.call(reset, moves_world=True)
    if op == "check":
        settle = float(kw.get("settle_s", 1.0))

        def check(robot: Any) -> dict[str, Any]:
            result = robot.check_subtask(settle_s=settle)
            return {"success": bool(result.success), "reason": str(result.reason)}

        return backend.call(check)
    if op == "object_poses":
        return backend.call(lambda robot: {n: list(p.xyz) for n, p in robot.object_poses().items()})
    if op == "state":
        return backend.call(lambda robot: robot.state().tolist())
    if op == "inject":
        faults[kw["device"]].inject(kw["kind"], kw.get("rate", 1.0))
        return None
    if op == "clear":
        faults[kw["device"]].clear(kw.get("kind"))
        return None
    raise ValueError(f"fake rig: unknown request {op!r}")


def _person(backend: Any, op: str, kw: dict[str, Any], person: dict[str, Any]) -> Any:
    """What the person at the rig does for a calibration (see :mod:`hw_drivers.fakes.calibration_person`)."""
    from hw_drivers.fakes.calibration_person import BoardPresenter, place_board

    presenter = person.get("presenter")
    if op == "presented":
        return {"shown": presenter.shown, "running": presenter.running} if presenter else {"shown": 0, "running": False}
    if presenter is not None:  # whatever the person does next, they stop presenting first
        presenter.stop()
        person["presenter"] = None
    if op == "board":
        place_board(backend, kw["board"], kw["where"])
        person["where"] = kw["where"]
        return None
    if person.get("where") != "hand":
        raise ValueError("present: the board is not in the person's hand (board(where='hand') first)")
    person["presenter"] = BoardPresenter(
        backend, person["rig"], kw["board"], count=kw["count"], seed=kw["seed"], hold_s=kw["hold_s"]
    ).start()
    return {"poses": len(person["presenter"].poses)}


# ---------------------------------------------------------------------------------------------- parent


class FakeRig:
    """Starts and talks to the fake rig process for a rig file with a ``hardware.fake`` section."""

    def __init__(self, rig_path: str | Path, *, seed: int = 0, subtask: int = 0, start_timeout: float = 60.0) -> None:
        self.rig_path = str(rig_path)
        self.seed, self.subtask = seed, subtask
        self.start_timeout = start_timeout
        self._proc: Any = None
        self._conn: Connection | None = None
        self.endpoints: FakeEndpoints | None = None

    def start(self) -> FakeEndpoints:
        ctx = mp.get_context("spawn")
        parent, child = ctx.Pipe()
        self._proc = ctx.Process(
            target=_serve, args=(child, self.rig_path, self.seed, self.subtask), name="fake-rig", daemon=True
        )
        try:
            self._proc.start()
        except BaseException:
            self._proc = None  # never started: nothing to join in stop()
            parent.close()
            raise
        finally:
            child.close()
        self._conn = parent
        try:
            status, payload = self._receive("start-up", self.start_timeout, "did not start")
        except (DeviceTimeoutError, FakeRigError):
            self.stop()
            raise
        if status != "ok":
            self.stop()
            raise FakeRigError("fake rig", f"failed to start:\n{payload}")
        assert isinstance(payload, FakeEndpoints)
        self.endpoints = payload
        return payload

    def request(self, op: str, timeout: float = 60.0, **kwargs: Any) -> Any:
        if self._conn is None:
            raise FakeRigError("fake rig", "not started")
        try:
            self._conn.send((op, kwargs))
        except (BrokenPipeError, EOFError, OSError):
            raise self._exited(f"before {op!r}") from None
        status, payload = self._receive(repr(op), timeout, f"no answer to {op!r}")
        if status != "ok":
            raise FakeRigError("fake rig", f"{op} failed:\n{payload}")
        return payload

    def _receive(self, what: str, timeout: float, late: str) -> tuple[str, Any]:
        """One reply from the process; a timeout or a dead process is a typed error, never a raw EOFError."""
        assert self._conn is not None
        try:
            if not self._conn.poll(timeout):
                raise DeviceTimeoutError("fake rig", f"{late} within {timeout} s")
            status, payload = self._conn.recv()
        except (EOFError, BrokenPipeError, ConnectionResetError):
            # The process died before it answered (it failed to import, was killed, crashed): say so, with its code.
            raise self._exited(f"during {what}") from None
        return status, payload

    def _exited(self, when: str) -> FakeRigError:
        code = None
        if self._proc is not None:
            self._proc.join(10.0)
            code = self._proc.exitcode
        return FakeRigError("fake rig", f"its process exited {when} (exit code {code})")

    # What a person does at a real rig, and what only a simulator can tell.
    def reset(self, task: str, seed: int, subtask: int) -> dict[str, Any]:
        """Set up a subtask's scene (objects placed, arms at the start); returns its start state."""
        return dict(self.request("reset", task=task, seed=seed, subtask=subtask))

    def check(self, settle_s: float = 1.0) -> dict[str, Any]:
        """The simulator's privileged checker on the current scene."""
        return dict(self.request("check", settle_s=settle_s))

    def object_poses(self) -> dict[str, list[float]]:
        return dict(self.request("object_poses"))

    def timing(self) -> dict[str, float]:
        """How well the fake rig kept the wall clock since it started or last reset a scene, in seconds (a loaded
        machine shows here, no real rig does): ``physics_lag_max_s``, the most the simulation ran behind;
        ``controller_gap_max_s``, the longest pause between two of a fake UR controller's 2 ms cycles."""
        return {k: float(v) for k, v in self.request("timing").items()}

    # The person at the rig during a calibration (hw_drivers.fakes.calibration_person).
    def board(self, where: str | None, board: str | Path) -> None:
        """Mount the board (config ``board``) on the ``left``/``right`` gripper, take it in ``hand``, or remove it."""
        self.request("board", where=where, board=str(board))

    def present_board(self, board: str | Path, *, count: int = 40, seed: int = 0, hold_s: float = 1.0) -> int:
        """Start holding the hand board up to the head camera, ``count`` poses of ``hold_s`` each; returns the count."""
        return int(self.request("present", board=str(board), count=count, seed=seed, hold_s=hold_s)["poses"])

    def presented(self) -> dict[str, Any]:
        """``{"shown": poses presented so far, "running": still presenting}``."""
        return dict(self.request("presented"))

    def inject(self, device: str, kind: str, rate: float = 1.0) -> None:
        if device not in DEVICES:
            raise ValueError(f"device: expected one of {DEVICES}, got {device!r}")
        self.request("inject", device=device, kind=kind, rate=rate)

    def clear(self, device: str, kind: str | None = None) -> None:
        self.request("clear", device=device, kind=kind)

    def stop(self) -> None:
        """Stop the fakes and the process (bounded; killed if it does not exit); idempotent."""
        if self._conn is not None:
            try:
                self._conn.send(("stop", {}))
                self._conn.poll(10.0)
            except (OSError, EOFError, BrokenPipeError):
                pass
            self._conn.close()
            self._conn = None
        if self._proc is not None:
            self._proc.join(10.0)
            if self._proc.is_alive():
                self._proc.kill()
                self._proc.join(5.0)
            self._proc = None

    def __enter__(self) -> FakeRig:
        self.start()
        return self

    def __exit__(self, *exc: object) -> None:
        self.stop()
