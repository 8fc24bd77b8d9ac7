"""The devices a calibration drives on a hardware rig, through the real drivers (or the protocol fakes).

A rig file with a ``hardware:`` section names the drivers (``ur_rtde`` arms, Dynamixel / Robotiq grippers,
``OpenCVCamera`` cameras); with ``hardware.fake`` the fake rig process is started first and the drivers talk
to its protocol fakes, exactly as :class:`pilworld.paired.stations.HardwareStation` does for a paired run.

On the fake rig the simulator also stands in for the *person* at the rig (``FakeRig.board``,
``FakeRig.present_board``): it mounts the board on a gripper, or holds it up to the camera, where a real
operator is asked to. :func:`person_prompt` is how the commands ask a real operator.

Frames for a calibration are the camera's **full-resolution** frames (``Camera.read_latest``), not the
letterboxed policy images of ``observe()``.
"""

from __future__ import annotations

import sys
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import numpy.typing as npt

from pilworld.config.rig import RigConfig

__all__ = [
    "CollectionStoppedError",
    "RigCamera",
    "RigRobot",
    "hardware_rig",
    "is_fake",
    "open_camera",
    "open_robot",
    "person_prompt",
]


class CollectionStoppedError(RuntimeError):
    """A device fault, a refusal or Ctrl-C ended a calibration collection; what was recorded is kept.

    The message is one line: what stopped it, how many views are kept where, and how to resume.
    """


def hardware_rig(rig_path: str | Path, what: str) -> RigConfig:
    """The rig config, which must have a ``hardware:`` section (``what`` names the command in the error)."""
    rig = RigConfig.load(rig_path)
    if rig.hardware is None:
        raise ValueError(
            f"{what}: rig {rig.name!r} ({rig_path}) has no 'hardware:' section, so there is no camera or robot to "
            "drive; on the simulated rig use the commands without --live (see docs/calibration.md), or pass a "
            "hardware rig such as configs/rig/fake_dual_ur5e.yaml"
        )
    return rig


def is_fake(rig: RigConfig) -> bool:
    return rig.hardware is not None and rig.hardware.fake is not None


@dataclass
class RigCamera:
    """One connected camera of a hardware rig; ``fake`` is the fake rig process when there is one."""

    name: str
    camera: Any  # hw_drivers.cameras.opencv.OpenCVCamera
    max_age: float
    fake: Any = None  # hw_drivers.fakes.rig.FakeRig

    def grab(self) -> tuple[npt.NDArray[np.uint8], int]:
        """The newest full-resolution frame (RGB) and its index; a stale or lost stream raises, typed."""
        frame = self.camera.read_latest(self.max_age)
        return np.asarray(frame.image, dtype=np.uint8), int(frame.index)


@contextmanager
def open_camera(rig_path: str | Path, name: str, *, what: str = "--live") -> Iterator[RigCamera]:
    """Connect camera ``name`` of a hardware rig (starting the fake rig first if it is one); closes it after."""
    from hw_drivers.factory import build_cameras

    rig = hardware_rig(rig_path, what)
    if name not in rig.cameras:
        raise ValueError(f"--camera: rig {rig.name!r} has no camera {name!r} (its cameras: {', '.join(rig.cameras)})")
    assert rig.hardware is not None
    with _fake_rig(rig, rig_path) as (fake, endpoints):
        camera = build_cameras(rig, endpoints)[name]
        camera.connect()
        try:
            yield RigCamera(name, camera, rig.hardware.max_age, fake)
        finally:
            camera.disconnect()


@contextmanager
def _fake_rig(rig: RigConfig, rig_path: str | Path) -> Iterator[tuple[Any, Any]]:
    """(the fake rig process, its endpoints) for a rig with ``hardware.fake``, else (None, None); stopped after."""
    if rig.hardware is None or rig.hardware.fake is None:
        yield None, None
        return
    from hw_drivers.fakes.rig import FakeRig

    fake = FakeRig(rig_path)
    endpoints = fake.start()
    try:
        yield fake, endpoints
    finally:
        fake.stop()


def person_prompt(message: str, *, ask: Callable[[str], str] = input) -> None:
    """Ask the operator at a real rig to do something and press Enter (refused without a terminal)."""
    if not sys.stdin.isatty():
        raise RuntimeError(f"{message} — but there is no terminal to confirm at (run it at the rig)")
    ask(f"{message}; press Enter when done ")


@dataclass
class RigRobot:
    """The connected robot of a hardware rig (arms, grippers, cameras) and the fake rig process, if any."""

    rig: RigConfig
    robot: Any  # hw_drivers.dual_arm.DualArmRobot
    fake: Any = None  # hw_drivers.fakes.rig.FakeRig

    def grab(self, camera: str, after: float | None = None, timeout: float = 5.0) -> npt.NDArray[np.uint8]:
        """A full-resolution frame of ``camera`` exposed after ``after`` (``time.monotonic()``), RGB.

        Waiting for a frame newer than the moment the arm settled keeps motion out of the image. A frame's
        timestamp is when it arrived, not when it was exposed, and a camera's pipeline (its buffer, an encoder,
        the network) holds a frame or so: the first frame to arrive after ``after`` may show the arm still
        moving, so it is passed over and the next one taken. A stale or lost stream raises the driver's typed
        error (after stopping the arms, as every device error does).
        """
        import time

        cam = self.robot.cameras[camera]
        assert self.rig.hardware is not None
        deadline = time.monotonic() + timeout
        first: int | None = None  # the index of the first frame to arrive after ``after``
        while True:
            try:
                frame = cam.read_latest(self.rig.hardware.max_age)
            except Exception:
                self.robot.stop()
                raise
            if after is None:
                return np.asarray(frame.image, dtype=np.uint8)
            if frame.timestamp > after:
                if first is None:
                    first = frame.index
                elif frame.index > first:
                    return np.asarray(frame.image, dtype=np.uint8)
            if time.monotonic() > deadline:
                from hw_drivers.errors import DeviceTimeoutError

                self.robot.stop()
                raise DeviceTimeoutError(camera, f"no new frame within {timeout} s")
            time.sleep(0.01)


@contextmanager
def open_robot(rig_path: str | Path, *, what: str = "calibration") -> Iterator[RigRobot]:
    """Connect a hardware rig through its drivers (the fake rig started first); arms stopped and closed after."""
    from hw_drivers.factory import build_robot

    rig = hardware_rig(rig_path, what)
    with _fake_rig(rig, rig_path) as (fake, endpoints):
        robot = build_robot(rig, endpoints)
        robot.connect()
        try:
            yield RigRobot(rig, robot, fake)
        finally:
            robot.disconnect()
