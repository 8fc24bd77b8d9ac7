"""Writing AV1 video leaves this process's scheduling as it was (pilworld.io.scheduling)."""

from __future__ import annotations

import os
import threading
from fractions import Fraction
from pathlib import Path

import av
import numpy as np
import pytest

from pilworld.data.video_codec import encode_video
from pilworld.io.scheduling import RealTimeGuard, real_time_threads

ROOT_ONLY = pytest.mark.skipif(os.geteuid() != 0, reason="only root may set a real-time policy")


def _frames(n: int = 6) -> np.ndarray:
    return np.random.default_rng(0).integers(0, 255, (n, 64, 64, 3), dtype=np.uint8)


def _raw_svt_encode(path: Path) -> None:
    """libsvtav1 through PyAV with no guard: what made a test process SCHED_FIFO 99."""
    with av.open(str(path), mode="w", format="mp4") as container:
        stream = container.add_stream("libsvtav1", rate=Fraction(10, 1))
        assert isinstance(stream, av.VideoStream)
        stream.width = stream.height = 64
        stream.pix_fmt = "yuv420p"
        for i, image in enumerate(_frames()):
            frame = av.VideoFrame.from_ndarray(image, format="rgb24")
            frame.pts = i
            for packet in stream.encode(frame):
                container.mux(packet)
        for packet in stream.encode():
            container.mux(packet)


@ROOT_ONLY
def test_the_hazard_is_real_svt_av1_makes_threads_real_time(tmp_path: Path) -> None:
    # The control: without the guard, encoding as root leaves real-time threads behind (if a new libsvtav1
    # stops doing this, the guard below is moot, not wrong).
    guard = RealTimeGuard()
    try:
        _raw_svt_encode(tmp_path / "raw.mp4")
        policy, left = os.sched_getscheduler(0), real_time_threads()
    finally:
        restored = guard.restore()  # always, so a failure here cannot leave the test process real-time
    assert policy == os.SCHED_FIFO and left, "libsvtav1 no longer sets SCHED_FIFO"
    assert restored >= 1
    assert os.sched_getscheduler(0) == os.SCHED_OTHER and not real_time_threads()


@pytest.mark.parametrize("mode", ["av1", "h264", "lossless"])
def test_encode_video_leaves_no_real_time_thread(tmp_path: Path, mode: str) -> None:
    before = os.sched_getscheduler(0)
    encode_video(_frames(), tmp_path / f"{mode}.mp4", fps=10, mode=mode)
    assert os.sched_getscheduler(0) == before
    assert not real_time_threads()
    # and a thread started afterwards (it inherits the creator's policy) is not real-time either
    seen: list[int] = []
    t = threading.Thread(target=lambda: seen.append(os.sched_getscheduler(0)))
    t.start()
    t.join()
    assert seen == [before]


@ROOT_ONLY
def test_the_guard_restores_only_what_became_real_time() -> None:
    already = threading.Event()
    stop = threading.Event()
    tids: dict[str, int] = {}

    def idle() -> None:
        tids["early"] = threading.get_native_id()
        already.set()
        stop.wait(10)

    early = threading.Thread(target=idle)
    early.start()
    already.wait(5)
    os.sched_setscheduler(tids["early"], os.SCHED_RR, os.sched_param(1))  # real-time before the guard
    try:
        guard = RealTimeGuard()
        os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(10))  # this thread: after the guard
        assert guard.restore() == 1
        assert os.sched_getscheduler(0) == os.SCHED_OTHER
        assert os.sched_getscheduler(tids["early"]) == os.SCHED_RR
        assert guard.restore() == 0
    finally:
        os.sched_setscheduler(tids["early"], os.SCHED_OTHER, os.sched_param(0))
        stop.set()
        early.join()
