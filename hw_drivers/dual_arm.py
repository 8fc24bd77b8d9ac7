"""``DualArmRobot``: two arms, two grippers and the cameras composed into the 14-d ``Robot`` contract.

Layout (:mod:`pilworld.types`): ``[left arm 6, left grip, right arm 6, right grip]``; grips are the
normalised opening (0 closed … 1 open). The parts run on their own clocks — each UR arm's 500 Hz
servo loop in its own process, each gripper's I/O thread, each camera's capture thread — and this
class only exchanges the latest values with them, so one slow device never stalls the others.

* :meth:`observe` reads every part's latest value and refuses stale ones (``max_age``): a policy is
  never handed an old frame or joint reading.
* :meth:`send_action` streams the arm targets and the gripper targets and returns what was sent
  (the grippers clip to 0 … 1).
* Any error from a part stops everything (:meth:`stop`) before it propagates, typed, naming the part.
* :meth:`move_to` brings the arms to a pose at a capped speed (the start pose before a subtask).
"""

from __future__ import annotations

import functools
import time
from collections.abc import Callable, Mapping
from types import TracebackType
from typing import TypeVar

import cv2
import numpy as np
from numpy.typing import NDArray

from hw_drivers.arm import Arm
from hw_drivers.cameras.base import Camera
from hw_drivers.errors import DeviceAlreadyConnectedError, DeviceNotConnectedError, DeviceTimeoutError, RobotError
from hw_drivers.grippers.base import Gripper
from pilworld.types import ARM_LAYOUT, STATE_DIM, Observation, RobotSpec

SIDES = ("left", "right")
T = TypeVar("T")


def letterbox(image: NDArray[np.uint8], size: tuple[int, int]) -> NDArray[np.uint8]:
    """Resize ``image`` to ``size`` (width, height) keeping its aspect, padding with black (openpi's rule).

    A calibrated head camera's model is letterboxed the same way (``RigConfig.head_camera_model``).
    """
    w, h = size
    ih, iw = image.shape[:2]
    if (iw, ih) == (w, h):
        return image
    scale = min(w / iw, h / ih)
    nw, nh = max(1, round(iw * scale)), max(1, round(ih * scale))
    resized = cv2.resize(image, (nw, nh), interpolation=cv2.INTER_AREA if scale < 1 else cv2.INTER_LINEAR)
    out = np.zeros((h, w, 3), dtype=np.uint8)
    y0, x0 = (h - nh) // 2, (w - nw) // 2
    out[y0 : y0 + nh, x0 : x0 + nw] = resized
    return out


class DualArmRobot:
    """The real rig (or its protocol fakes) as one :class:`~hw_drivers.robot.Robot`."""

    def __init__(
        self,
        spec: RobotSpec,
        arms: Mapping[str, Arm],
        grippers: Mapping[str, Gripper],
        cameras: Mapping[str, Camera],
        *,
        max_age: float = 0.25,
        name: str = "dual_arm",
    ) -> None:
        if spec.dof != STATE_DIM:
            raise ValueError(f"spec: a dual-arm robot has {STATE_DIM} joints, the spec has {spec.dof}")
        for what, parts in (("arms", arms), ("grippers", grippers)):
            if set(parts) != set(SIDES):
                raise ValueError(f"{what}: expected exactly {SIDES}, got {sorted(parts)}")
        missing = [c for c in spec.cameras if c not in cameras]
        if missing:
            raise ValueError(f"cameras: the spec's cameras {missing} have no device")
        if max_age <= 0:
            raise ValueError(f"max_age: expected > 0, got {max_age}")
        self._spec = spec
        self.arms = dict(arms)
        self.grippers = dict(grippers)
        self.cameras = {c: cameras[c] for c in spec.cameras}
        self.max_age = max_age
        self.name = name
        self._connected = False
        self._last_sent: NDArray[np.float32] | None = None

    # ------------------------------------------------------------------ connection

    @property
    def spec(self) -> RobotSpec:
        return self._spec

    @property
    def is_connected(self) -> bool:
        return self._connected

    def _parts(self) -> list[Arm | Gripper | Camera]:
        return [*self.arms.values(), *self.grippers.values(), *self.cameras.values()]

    def connect(self) -> None:
        """Connect every part; if one fails, the ones already connected are disconnected again."""
        if self._connected:
            raise DeviceAlreadyConnectedError(self.name, "already connected")
        done: list[Arm | Gripper | Camera] = []
        try:
            for part in self._parts():
                part.connect()
                done.append(part)
        except BaseException:
            for part in reversed(done):
                self._quietly(part.disconnect)
            raise
        self._connected = True
        self._last_sent = None

    def disconnect(self) -> None:
        """Stop the arms, then disconnect every part (each tried even if another fails); idempotent."""
        if not self._connected:
            return
        self._connected = False
        errors: list[BaseException] = []
        for arm in self.arms.values():
            self._quietly(arm.stop, errors)
        for part in self._parts():
            self._quietly(part.disconnect, errors)
        if errors:
            raise errors[0]

    def __enter__(self) -> DualArmRobot:
        self.connect()
        return self

    def __exit__(
        self, exc_type: type[BaseException] | None, exc: BaseException | None, tb: TracebackType | None
    ) -> None:
        self.disconnect()

    @staticmethod
    def _quietly(fn: Callable[[], object], errors: list[BaseException] | None = None) -> None:
        try:
            fn()
        except Exception as e:  # collected: one part's failure must not keep the others running
            if errors is not None:
                errors.append(e)

    def _require(self) -> None:
        if not self._connected:
            raise DeviceNotConnectedError(self.name, "not connected; call connect() or use it as a context manager")

    def _guarded(self, fn: Callable[[], T]) -> T:
        """Run ``fn``; on any robot error stop everything first, then re-raise it (typed, naming the part)."""
        try:
            return fn()
        except RobotError:
            self.stop()
            raise

    # ------------------------------------------------------------------ the Robot contract

    def clock(self) -> float:
        """The clock of observation timestamps (the safety filter's staleness rule)."""
        return time.monotonic()

    def state(self) -> NDArray[np.float32]:
        """The measured 14-d state (arms and grippers), refusing readings older than ``max_age``."""
        self._require()

        def read() -> NDArray[np.float32]:
            out = np.empty(STATE_DIM, dtype=np.float64)
            for side, (arm, grip) in ARM_LAYOUT.items():
                out[arm] = self.arms[side].state(self.max_age).q
                out[grip] = self.grippers[side].status(self.max_age).opening
            return out.astype(np.float32)

        return self._guarded(read)

    def observe(self) -> Observation:
        self._require()

        def read() -> Observation:
            images = {}
            oldest = np.inf
            for name, cam in self.cameras.items():
                frame = cam.read_latest(self.max_age)
                images[name] = letterbox(frame.image, self._spec.image_size)
                oldest = min(oldest, frame.timestamp)
            state = self.state()
            # The observation is as old as its oldest part: the safety filter's staleness rule uses it.
            return Observation(images=images, state=state, timestamp=float(oldest))

        return self._guarded(read)

    def send_action(self, action: NDArray[np.floating]) -> NDArray[np.float32]:
        """Stream one 14-d target to the arms and grippers; returns what was sent.

        This is below the safety filter (``RobotEnv`` applies it); it only checks the vector is usable.
        """
        self._require()
        a = np.asarray(action, dtype=np.float64)
        if a.shape != (STATE_DIM,) or not np.all(np.isfinite(a)):
            self.stop()
            raise ValueError(f"action: expected {STATE_DIM} finite values, got {a!r}")

        def send() -> NDArray[np.float32]:
            sent = a.copy()
            for side, (arm, grip) in ARM_LAYOUT.items():
                self.arms[side].set_target(a[arm])
                sent[grip] = self.grippers[side].set_target(float(a[grip]))
            return sent.astype(np.float32)

        self._last_sent = self._guarded(send)
        return self._last_sent

    def stop(self) -> None:
        """Stop both arms now (decelerate and hold) and hold the grippers where they are; never raises."""
        for arm in self.arms.values():
            self._quietly(arm.stop)
        for gripper in self.grippers.values():
            self._quietly(functools.partial(self._hold, gripper))

    @staticmethod
    def _hold(gripper: Gripper) -> None:
        gripper.set_target(gripper.status(max_age=10.0).opening)

    # ------------------------------------------------------------------ start pose

    def move_to(self, q: NDArray[np.floating], *, speed: float = 0.3, timeout: float = 30.0) -> None:
        """Move to the 14-d pose ``q``: arms at no more than ``speed`` rad/s (blocking), grippers to their opening.

        Used before a subtask to reach its start pose; the arms move one after the other so a person
        watching sees one motion at a time.
        """
        self._require()
        target = np.asarray(q, dtype=np.float64)
        if target.shape != (STATE_DIM,) or not np.all(np.isfinite(target)):
            raise ValueError(f"q: expected {STATE_DIM} finite values, got {target!r}")
        if not 0 < speed <= 1.0:
            raise ValueError(f"speed: expected 0 < speed <= 1.0 rad/s for a move to the start, got {speed}")

        def move() -> None:
            for side, (arm, grip) in ARM_LAYOUT.items():
                self.grippers[side].set_target(float(target[grip]))
                self.arms[side].move_to(target[arm], speed, timeout)
            deadline = time.monotonic() + timeout
            for side, (_, grip) in ARM_LAYOUT.items():
                while abs(self.grippers[side].status(self.max_age).opening - float(target[grip])) > 0.03:
                    if time.monotonic() > deadline:
                        raise DeviceTimeoutError(
                            f"{side} gripper", f"did not reach opening {target[grip]:.2f} in {timeout} s"
                        )
                    time.sleep(0.02)

        self._guarded(move)
