"""The world behind the protocol fakes: one rig that every fake device reads and drives.

On a real rig the two UR controllers, the gripper buses and the cameras all look at one physical
scene. The fakes (:mod:`hw_drivers.fakes`) do the same through a :class:`RigBackend`:

* :class:`SimBackend` — the MuJoCo rig (:class:`simrig.robot.SimRobot`) stepped in real time by
  one thread that owns every MuJoCo call (an EGL context belongs to the thread that made it). Arm and
  gripper targets set by the fakes are tracked at the rig's control rate; cameras are rendered at
  ``camera_fps`` and served as "the latest frame" like a real camera.
* :class:`KinematicBackend` — no physics and no rendering: joints move toward their targets at a capped
  speed, computed on read, and frames are synthetic. For testing one fake device in isolation, fast.

All methods are thread-safe. Sides are ``"left"`` and ``"right"``; arm joints in radians (6 per arm,
UR order base→wrist 3); a gripper's opening is the normalised finger gap, 0 closed … 1 open (the
14-d state layout of :mod:`pilworld.types`).
"""

from __future__ import annotations

import queue
import threading
import time
from collections.abc import Callable
from concurrent.futures import Future
from typing import Any, Protocol, TypeVar, runtime_checkable

import numpy as np
from numpy.typing import NDArray

from pilworld.types import ARM_LAYOUT, DEFAULT_VIEWS, STATE_DIM

SIDES = ("left", "right")
T = TypeVar("T")


class BackendError(RuntimeError):
    """The backend is closed, or its simulation thread died (the message says why)."""


def check_side(side: str) -> str:
    if side not in SIDES:
        raise ValueError(f"side: expected one of {SIDES}, got {side!r}")
    return side


@runtime_checkable
class RigBackend(Protocol):
    """What a fake device sees of the world."""

    @property
    def cameras(self) -> tuple[str, ...]: ...

    def arm_q(self, side: str) -> NDArray[np.float64]:
        """Measured joint angles of one arm, shape (6,) [rad]."""
        ...

    def arm_qd(self, side: str) -> NDArray[np.float64]:
        """Measured joint velocities of one arm, shape (6,) [rad/s]."""
        ...

    def set_arm_target(self, side: str, q: NDArray[np.floating]) -> None:
        """The joint target the arm's controller tracks from now on, shape (6,) [rad]."""
        ...

    def gripper_opening(self, side: str) -> float:
        """Measured normalised finger gap, 0 closed … 1 open."""
        ...

    def set_gripper_target(self, side: str, opening: float) -> None:
        """The opening the gripper's servo tracks from now on (clipped to 0 … 1)."""
        ...

    def frame(self, camera: str) -> tuple[NDArray[np.uint8], float]:
        """The latest image of ``camera`` (H, W, 3 RGB) and its capture time (``time.monotonic()``)."""
        ...

    def close(self) -> None: ...


# ---------------------------------------------------------------------------------------------- kinematic


class KinematicBackend:
    """Joints slew toward their targets at ``arm_speed`` rad/s (grippers ``grip_speed`` /s); synthetic frames.

    Frame content encodes the camera and the left arm's first joint, so a test can tell frames apart
    and see them change when the arm moves.
    """

    def __init__(
        self,
        *,
        cameras: tuple[str, ...] = DEFAULT_VIEWS,
        image_size: tuple[int, int] = (128, 128),
        arm_speed: float = 1.0,
        grip_speed: float = 2.0,
        q0: NDArray[np.floating] | None = None,
    ) -> None:
        self._cameras = tuple(cameras)
        self._size = image_size
        self._speed = np.array([arm_speed] * 6 + [grip_speed], dtype=np.float64)
        start = np.zeros(STATE_DIM) if q0 is None else np.asarray(q0, dtype=np.float64)
        if start.shape != (STATE_DIM,):
            raise ValueError(f"q0: expected shape ({STATE_DIM},), got {start.shape}")
        self._q = start.copy()
        self._qd = np.zeros(STATE_DIM)
        self._target = start.copy()
        self._t = time.monotonic()
        self._lock = threading.Lock()
        self._closed = False

    @property
    def cameras(self) -> tuple[str, ...]:
        return self._cameras

    def _advance(self) -> None:
        now = time.monotonic()
        dt = now - self._t
        self._t = now
        if dt <= 0:
            return
        step = np.concatenate([self._speed, self._speed]) * dt
        new = self._q + np.clip(self._target - self._q, -step, step)
        self._qd = (new - self._q) / dt
        self._q = new

    def _check(self) -> None:
        if self._closed:
            raise BackendError("backend closed")

    def arm_q(self, side: str) -> NDArray[np.float64]:
        arm, _ = ARM_LAYOUT[check_side(side)]
        with self._lock:
            self._check()
            self._advance()
            return self._q[arm].copy()

    def arm_qd(self, side: str) -> NDArray[np.float64]:
        arm, _ = ARM_LAYOUT[check_side(side)]
        with self._lock:
            self._check()
            self._advance()
            return self._qd[arm].copy()

    def set_arm_target(self, side: str, q: NDArray[np.floating]) -> None:
        arm, _ = ARM_LAYOUT[check_side(side)]
        q = np.asarray(q, dtype=np.float64)
        if q.shape != (6,) or not np.all(np.isfinite(q)):
            raise ValueError(f"q: expected 6 finite joint angles, got {q!r}")
        with self._lock:
            self._check()
            self._advance()
            self._target[arm] = q

    def gripper_opening(self, side: str) -> float:
        _, grip = ARM_LAYOUT[check_side(side)]
        with self._lock:
            self._check()
            self._advance()
            return float(self._q[grip])

    def set_gripper_target(self, side: str, opening: float) -> None:
        _, grip = ARM_LAYOUT[check_side(side)]
        if not np.isfinite(opening):
            raise ValueError(f"opening: expected a finite number, got {opening!r}")
        with self._lock:
            self._check()
            self._advance()
            self._target[grip] = min(1.0, max(0.0, float(opening)))

    def frame(self, camera: str) -> tuple[NDArray[np.uint8], float]:
        if camera not in self._cameras:
            raise ValueError(f"camera: expected one of {self._cameras}, got {camera!r}")
        with self._lock:
            self._check()
            self._advance()
            level = int(127 + 120 * np.tanh(self._q[0]))
        w, h = self._size
        img = np.empty((h, w, 3), dtype=np.uint8)
        yy, xx = np.mgrid[0:h, 0:w]
        img[..., 0] = (xx * 255 // max(1, w - 1)).astype(np.uint8)
        img[..., 1] = (yy * 255 // max(1, h - 1)).astype(np.uint8)
        img[..., 2] = (level + 40 * self._cameras.index(camera)) % 256
        return img, time.monotonic()

    def close(self) -> None:
        with self._lock:
            self._closed = True


# ---------------------------------------------------------------------------------------------- simulated


class SimBackend:
    """The MuJoCo rig in real time, owned by one thread (see the module docstring).

    ``task``/``seed``/``subtask``: the scene set up at start (``SimRobot.reset``). :meth:`call` runs any
    function of the ``SimRobot`` on the simulation thread (reset a subtask, read the privileged checker).
    ``stream_sizes``: per camera, the (width, height) its frames are rendered at (same field of view).
    ``appearance``: the rig's look, ``"flat"`` or ``"varied"`` (``SimRobot``'s, see ``simrig.appearance``).
    """

    def __init__(
        self,
        rig: Any = None,
        task: str = "sort_cubes",
        *,
        seed: int = 0,
        subtask: int = 0,
        camera_fps: float = 10.0,
        stream_sizes: dict[str, tuple[int, int]] | None = None,
        start_timeout: float = 60.0,
        appearance: str = "flat",
    ) -> None:
        from simrig.files import SIM_RIG

        if camera_fps <= 0:
            raise ValueError(f"camera_fps: expected > 0, got {camera_fps}")
        self._rig_arg = SIM_RIG if rig is None else rig
        self._task = task
        self._seed, self._subtask = seed, subtask
        self._appearance = appearance  # the simulated rig's look (simrig.appearance): "flat" or "varied"
        self._camera_period = 1.0 / camera_fps
        # Per camera, (width, height) of the frames served (a real camera's full resolution); default the rig's.
        self._sizes = dict(stream_sizes or {})
        self._lock = threading.Lock()
        self._calls: queue.Queue[tuple[Callable[[Any], Any], Future[Any], bool]] = queue.Queue()
        self._stop = threading.Event()
        self._ready = threading.Event()
        self._error: BaseException | None = None
        self._state = np.zeros(STATE_DIM)
        self._qd = np.zeros(STATE_DIM)
        self._target = np.zeros(STATE_DIM)
        self._frames: dict[str, tuple[NDArray[np.uint8], float]] = {}
        self._cameras: tuple[str, ...] = ()
        self.control_rate_hz = 0.0
        self._lag_max = 0.0  # how far physics fell behind the wall clock [s] (see timing())
        self._thread = threading.Thread(target=self._run, name="sim-backend", daemon=True)
        self._thread.start()
        if not self._ready.wait(start_timeout):
            self.close()
            raise BackendError(f"the simulated rig did not start within {start_timeout} s")
        if self._error is not None:
            raise BackendError(f"the simulated rig failed to start: {self._error}") from self._error

    # -- the simulation thread

    def _run(self) -> None:
        from simrig.robot import SimRobot

        try:
            robot = SimRobot(self._rig_arg, self._task, appearance=self._appearance)
            robot.connect()
            robot.reset(seed=self._seed, subtask=self._subtask, history=0)
            self._cameras = robot.spec.cameras
            self.control_rate_hz = robot.spec.control_rate_hz
            with self._lock:
                self._state = robot.state().astype(np.float64)
                self._target = self._state.copy()
            self._render_all(robot)
        except BaseException as e:  # reported by __init__
            self._error = e
            self._ready.set()
            return
        self._ready.set()
        period = 1.0 / self.control_rate_hz
        next_tick = time.monotonic()
        next_frame = next_tick + self._camera_period
        try:
            while not self._stop.is_set():
                if self._serve_calls(robot):
                    # A scene reset is a pause of the world, not lag: the clock and the record start afresh.
                    next_tick = time.monotonic()
                    with self._lock:
                        self._lag_max = 0.0
                now = time.monotonic()
                if now < next_tick:
                    time.sleep(min(next_tick - now, 0.002))
                    continue
                # Behind real time (a slow machine): catch up by stepping, never by skipping physics.
                lag = now - next_tick
                next_tick += period
                with self._lock:
                    target = self._target.copy()
                    self._lag_max = max(self._lag_max, lag)
                before = robot.state().astype(np.float64)
                robot.send_action(target)
                after = robot.state().astype(np.float64)
                with self._lock:
                    self._state = after
                    self._qd = (after - before) / period
                # Physics first: while it is a step or more behind, a frame waits (a camera drops frames under
                # load; an arm does not stop) — but never for more than three frame periods, so frames stay fresh.
                now = time.monotonic()
                behind = now - next_tick > period
                if now >= next_frame and (not behind or now >= next_frame + 2 * self._camera_period):
                    self._render_all(robot)
                    next_frame = time.monotonic() + self._camera_period
        except BaseException as e:
            self._error = e
        finally:
            self._fail_pending(self._error)
            robot.disconnect()

    def _render_all(self, robot: Any) -> None:
        frames = {}
        for cam in robot.spec.cameras:
            frames[cam] = (robot.render(cam, *self._sizes.get(cam, (None, None))), time.monotonic())
        with self._lock:
            self._frames.update(frames)

    def _serve_calls(self, robot: Any) -> bool:
        """Run the queued calls; whether one of them moved the world."""
        moved = False
        while True:
            try:
                fn, fut, moves_world = self._calls.get_nowait()
            except queue.Empty:
                return moved
            if not fut.set_running_or_notify_cancel():
                continue
            try:
                result = fn(robot)
            except BaseException as e:
                fut.set_exception(e)
                continue
            if not moves_world:  # a reading: the world, the targets and the frames are as they were
                fut.set_result(result)
                continue
            # A reset moves the world: targets follow it, so nothing yanks the arms back.
            moved = True
            state = robot.state().astype(np.float64)
            with self._lock:
                self._state = state
                self._qd = np.zeros(STATE_DIM)
                self._target = robot.command().astype(np.float64)
            self._render_all(robot)
            fut.set_result(result)

    def _fail_pending(self, error: BaseException | None) -> None:
        while True:
            try:
                _, fut, _ = self._calls.get_nowait()
            except queue.Empty:
                return
            fut.set_exception(BackendError(f"simulation stopped: {error}" if error else "backend closed"))

    # -- the RigBackend interface

    def _check(self) -> None:
        if self._error is not None:
            raise BackendError(f"the simulation thread died: {self._error!r}")
        if self._stop.is_set():
            raise BackendError("backend closed")

    @property
    def cameras(self) -> tuple[str, ...]:
        return self._cameras

    def call(self, fn: Callable[[Any], T], timeout: float = 30.0, *, moves_world: bool = False) -> T:
        """``fn(sim_robot)`` on the simulation thread; its result (or exception).

        ``moves_world``: ``fn`` changes the scene (a reset), so the arm and gripper targets are set to
        where the robot now stands and the cameras are rendered again; a reading leaves both alone.
        """
        self._check()
        fut: Future[T] = Future()
        self._calls.put((fn, fut, moves_world))
        return fut.result(timeout)

    def arm_q(self, side: str) -> NDArray[np.float64]:
        arm, _ = ARM_LAYOUT[check_side(side)]
        self._check()
        with self._lock:
            return self._state[arm].copy()

    def arm_qd(self, side: str) -> NDArray[np.float64]:
        arm, _ = ARM_LAYOUT[check_side(side)]
        self._check()
        with self._lock:
            return self._qd[arm].copy()

    def set_arm_target(self, side: str, q: NDArray[np.floating]) -> None:
        arm, _ = ARM_LAYOUT[check_side(side)]
        q = np.asarray(q, dtype=np.float64)
        if q.shape != (6,) or not np.all(np.isfinite(q)):
            raise ValueError(f"q: expected 6 finite joint angles, got {q!r}")
        self._check()
        with self._lock:
            self._target[arm] = q

    def gripper_opening(self, side: str) -> float:
        _, grip = ARM_LAYOUT[check_side(side)]
        self._check()
        with self._lock:
            return float(self._state[grip])

    def set_gripper_target(self, side: str, opening: float) -> None:
        _, grip = ARM_LAYOUT[check_side(side)]
        if not np.isfinite(opening):
            raise ValueError(f"opening: expected a finite number, got {opening!r}")
        self._check()
        with self._lock:
            self._target[grip] = min(1.0, max(0.0, float(opening)))

    def frame(self, camera: str) -> tuple[NDArray[np.uint8], float]:
        self._check()
        with self._lock:
            if camera not in self._frames:
                raise ValueError(f"camera: expected one of {self._cameras}, got {camera!r}")
            img, t = self._frames[camera]
        return img, t

    def timing(self) -> dict[str, float]:
        """How well the simulation kept the wall clock since it started or last reset its scene:
        ``physics_lag_max_s``, the most its physics ran behind (it catches up by stepping, so commands sent
        meanwhile take effect late)."""
        with self._lock:
            return {"physics_lag_max_s": self._lag_max}

    def close(self) -> None:
        self._stop.set()
        if threading.current_thread() is not self._thread:
            self._thread.join(10.0)

    def __enter__(self) -> SimBackend:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()
