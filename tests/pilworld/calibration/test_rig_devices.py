"""RigRobot.grab: the frame taken after the arm settled is the second to arrive after it (docs/calibration.md)."""

from __future__ import annotations

import time
from types import SimpleNamespace

import numpy as np
import pytest

from hw_drivers.cameras.base import Frame
from hw_drivers.errors import DeviceTimeoutError
from pilworld.calibration.rig_devices import RigRobot


class Camera:
    """Hands out scripted frames, one per read (the last one for ever after)."""

    def __init__(self, frames: list[Frame]) -> None:
        self.frames = frames
        self.reads = 0

    def read_latest(self, max_age: float) -> Frame:
        frame = self.frames[min(self.reads, len(self.frames) - 1)]
        self.reads += 1
        return frame


class Robot:
    def __init__(self, camera: Camera) -> None:
        self.cameras = {"cam_high": camera}
        self.stopped = 0

    def stop(self) -> None:
        self.stopped += 1


def _frame(index: int, timestamp: float) -> Frame:
    return Frame(image=np.full((2, 2, 3), index, dtype=np.uint8), timestamp=timestamp, index=index)


def _rig(camera: Camera) -> RigRobot:
    return RigRobot(rig=SimpleNamespace(hardware=SimpleNamespace(max_age=1.0)), robot=Robot(camera))  # type: ignore[arg-type]


def test_the_first_frame_to_arrive_after_settling_is_passed_over() -> None:
    # Frame 1 arrived before the arm settled; frame 2 after it (exposed, perhaps, while the arm still moved); frame 3
    # was exposed after frame 2 arrived.
    camera = Camera([_frame(1, 9.0), _frame(2, 10.5), _frame(2, 10.5), _frame(3, 10.6)])
    image = _rig(camera).grab("cam_high", after=10.0)
    assert int(image[0, 0, 0]) == 3 and camera.reads == 4


def test_without_a_moment_the_newest_frame_is_taken() -> None:
    assert int(_rig(Camera([_frame(7, 1.0)])).grab("cam_high")[0, 0, 0]) == 7


def test_a_stream_that_brings_one_frame_only_times_out_and_stops_the_arms() -> None:
    rig = _rig(Camera([_frame(1, time.monotonic() + 100.0)]))  # one new frame, then nothing newer
    with pytest.raises(DeviceTimeoutError, match=r"no new frame within 0\.05 s"):
        rig.grab("cam_high", after=0.0, timeout=0.05)
    assert rig.robot.stopped == 1
