"""Test helper: a FakeURController with a KinematicBackend in a spawned child process, driven over a pipe.

The ur_rtde client (URArm's worker) and the fake must never share a process (the client's constructors hold
the GIL), and the fake in a process of its own also behaves like a separate controller for timing.
Each fake binds a random 127.x.y.z so parallel test runs do not collide on the fixed ports.
"""

from __future__ import annotations

import contextlib
import multiprocessing as mp
import random
import time
from multiprocessing.connection import Connection
from multiprocessing.process import BaseProcess
from typing import Any

import numpy as np


def random_host() -> str:
    return f"127.{random.randint(1, 254)}.{random.randint(1, 254)}.{random.randint(2, 254)}"


def _serve(conn: Connection, host: str, side: str, arm_speed: float) -> None:
    from hw_drivers.fakes.backend import KinematicBackend
    from hw_drivers.fakes.ur_controller import FakeURController

    backend = KinematicBackend(arm_speed=arm_speed)
    fake = FakeURController(backend, side, host)
    try:
        fake.start()
    except OSError as e:
        conn.send(("error", str(e)))
        return
    conn.send(("ready", host))
    try:
        while True:
            try:
                request = conn.recv()
            except (EOFError, OSError):
                break  # the test process went away
            op = request[0]
            if op == "stop":
                break
            if op == "inject":
                fake.faults.inject(request[1], request[2])
            elif op == "clear":
                fake.faults.clear(request[1])
            elif op == "set_q":  # teleport (targets included), as if someone moved the arm
                backend.set_arm_target(side, np.asarray(request[1]))
            conn.send(
                {
                    "q": backend.arm_q(side).tolist(),
                    "qd": backend.arm_qd(side).tolist(),
                    "program_running": fake.program_running,
                    "safety": fake.safety,
                    "robot_mode": fake.robot_mode,
                    "servoing": fake.servoing,
                }
            )
    finally:
        fake.stop()
        backend.close()


class FakeURProcess:
    """``with FakeURProcess() as fake:`` → ``fake.host`` to connect to; ``inject``/``clear``/``status``."""

    def __init__(self, side: str = "left", arm_speed: float = 4.0) -> None:
        self.side, self.arm_speed = side, arm_speed
        self.host = ""
        self._proc: BaseProcess | None = None
        self._conn: Connection | None = None

    def start(self) -> FakeURProcess:
        ctx = mp.get_context("spawn")
        for _ in range(5):  # a random address may (rarely) be taken
            parent, child = ctx.Pipe()
            host = random_host()
            proc = ctx.Process(target=_serve, args=(child, host, self.side, self.arm_speed), daemon=True)
            proc.start()
            child.close()
            if not parent.poll(20.0):
                proc.kill()
                raise TimeoutError("fake UR controller did not start")
            reply = parent.recv()
            if reply[0] == "ready":
                self.host, self._proc, self._conn = host, proc, parent
                return self
            proc.join(5.0)
        raise OSError(f"fake UR controller could not bind: {reply[1]}")

    def _call(self, *request: Any) -> dict[str, Any]:
        assert self._conn is not None
        self._conn.send(request)
        if not self._conn.poll(10.0):
            raise TimeoutError(f"fake UR controller did not answer {request[0]}")
        reply: dict[str, Any] = self._conn.recv()
        return reply

    def status(self) -> dict[str, Any]:
        return self._call("status")

    def inject(self, kind: str, rate: float = 1.0) -> None:
        self._call("inject", kind, rate)

    def clear(self, kind: str | None = None) -> None:
        self._call("clear", kind)

    def wait_still(self, timeout: float = 2.0) -> dict[str, Any]:
        """The status once the arm has stopped moving (|qd| ~ 0 over 0.1 s); AssertionError otherwise."""
        deadline = time.monotonic() + timeout
        while True:
            a = self.status()
            time.sleep(0.1)
            b = self.status()
            if max(map(abs, b["qd"])) < 1e-9 and np.allclose(a["q"], b["q"], atol=1e-9):
                return b
            assert time.monotonic() < deadline, f"arm still moving: {b}"

    def stop(self) -> None:
        if self._proc is None:
            return
        if self._conn is not None:
            with contextlib.suppress(OSError):
                self._conn.send(("stop",))
            self._conn.close()
        self._proc.join(5.0)
        if self._proc.is_alive():
            self._proc.kill()
            self._proc.join(2.0)
        self._proc, self._conn = None, None

    def __enter__(self) -> FakeURProcess:
        return self.start()

    def __exit__(self, *exc: object) -> None:
        self.stop()
