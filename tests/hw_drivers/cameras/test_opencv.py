"""OpenCVCamera against the fake MJPEG server: content, frame counts, and every fault → a typed error in time.

Time bounds asserted here (server at 30 fps, read_timeout 1 s):
stall → StaleObservationError once max_age passes, DeviceTimeoutError within read_timeout + 0.5 s;
disconnect / server stop → DeviceConnectionError < 1 s; corrupt → DeviceProtocolError < 1.5 s;
unreachable URL → DeviceConnectionError < 1 s; a stream that never sends → DeviceTimeoutError at
connect_timeout (+0.5 s); read_latest returns in < 20 ms even while the stream is stalled.
"""

from __future__ import annotations

import contextlib
import socket
import time
from collections.abc import Callable, Iterator
from pathlib import Path

import cv2
import numpy as np
import pytest

from hw_drivers.cameras.base import Camera, Frame
from hw_drivers.cameras.opencv import OpenCVCamera
from hw_drivers.errors import (
    DeviceAlreadyConnectedError,
    DeviceConnectionError,
    DeviceNotConnectedError,
    DeviceProtocolError,
    DeviceTimeoutError,
    RobotError,
    StaleObservationError,
)
from hw_drivers.fakes.backend import KinematicBackend
from hw_drivers.fakes.faults import FaultSwitch
from hw_drivers.fakes.mjpeg_camera import MJPEGCameraServer

FPS = 30.0
SIZE = (96, 72)  # (width, height)


@pytest.fixture
def faults() -> FaultSwitch:
    return FaultSwitch()


@pytest.fixture
def server(faults: FaultSwitch) -> Iterator[MJPEGCameraServer]:
    backend = KinematicBackend(image_size=SIZE)
    with MJPEGCameraServer(backend, fps=FPS, faults=faults) as srv:
        yield srv
    backend.close()


@pytest.fixture
def make_camera(server: MJPEGCameraServer) -> Iterator[Callable[..., OpenCVCamera]]:
    cams: list[OpenCVCamera] = []

    def make(camera: str = "cam_high", **kw: object) -> OpenCVCamera:
        kw.setdefault("read_timeout", 1.0)
        kw.setdefault("connect_timeout", 2.0)
        cam = OpenCVCamera(camera, server.url(camera), **kw)  # type: ignore[arg-type]
        cams.append(cam)
        cam.connect()
        return cam

    yield make
    for cam in cams:
        cam.disconnect()


def first_error(cam: OpenCVCamera, max_age: float, within: float) -> tuple[RobotError | None, float]:
    """Poll read_latest until it raises; (the error, seconds it took), or (None, within)."""
    t0 = time.monotonic()
    while time.monotonic() - t0 < within:
        try:
            cam.read_latest(max_age)
        except RobotError as e:
            return e, time.monotonic() - t0
        time.sleep(0.01)
    return None, within


def wait_for(cam: OpenCVCamera, kind: type[RobotError], within: float, max_age: float = 10.0) -> float:
    """Seconds until read_latest raises ``kind`` (other errors are skipped); fails after ``within``."""
    t0 = time.monotonic()
    while time.monotonic() - t0 < within:
        try:
            cam.read_latest(max_age)
        except kind:
            return time.monotonic() - t0
        except RobotError:
            pass
        time.sleep(0.01)
    pytest.fail(f"no {kind.__name__} within {within} s")


def fresh(cam: OpenCVCamera, within: float = 2.0) -> Frame:
    t0 = time.monotonic()
    while True:
        try:
            return cam.read_latest(0.2)
        except StaleObservationError:
            if time.monotonic() - t0 > within:
                raise
            time.sleep(0.01)


def test_frames_arrive_in_rgb_order(make_camera: Callable[..., OpenCVCamera]) -> None:
    cam = make_camera("cam_left_wrist")
    assert isinstance(cam, Camera) and cam.is_connected
    a = fresh(cam)
    time.sleep(3 / FPS)
    b = fresh(cam)
    assert b.index > a.index and b.timestamp > a.timestamp
    assert time.monotonic() - b.timestamp < 0.2
    img = b.image.astype(int)
    assert b.image.dtype == np.uint8 and b.image.shape == (SIZE[1], SIZE[0], 3)
    # KinematicBackend: R rises left→right, G top→bottom, B = 127 + 40·(camera index); JPEG ±12.
    assert abs(img[:, 0, 0].mean()) < 12 and abs(img[:, -1, 0].mean() - 255) < 12
    assert abs(img[0, :, 1].mean()) < 12 and abs(img[-1, :, 1].mean() - 255) < 12
    assert abs(img[..., 2].mean() - 167) < 12


def test_resize_uses_requested_size(make_camera: Callable[..., OpenCVCamera]) -> None:
    cam = make_camera(resize_to=(48, 24))
    frame = fresh(cam)
    assert frame.image.shape == (24, 48, 3)
    assert frame.image[:, -1, 0].mean() > 200 and frame.image[:, 0, 0].mean() < 50  # still RGB


def frames_after(cam: OpenCVCamera, index: int, within: float = 10.0) -> Frame:
    """The newest frame once its index reaches ``index`` (a bound against hanging, not a speed check)."""
    t0 = time.monotonic()
    while (frame := cam.read_latest(10.0)).index < index:
        assert time.monotonic() - t0 < within, f"frame #{index} never arrived (newest #{frame.index})"
        time.sleep(0.01)
    return frame


def test_every_frame_sent_is_received(make_camera: Callable[..., OpenCVCamera], server: MJPEGCameraServer) -> None:
    # Counts, not a rate (the rate is `pilworld bench drivers`' camera_fps): the capture thread hands on
    # each part the server sent, none lost or repeated, and fps_measured counts what arrived.
    cam = make_camera()
    frame = frames_after(cam, fresh(cam).index + 20)
    sent = server.counts()["sent"]
    assert sent - 3 <= frame.index + 1 <= sent  # FFmpeg may hold a part or two in its buffer
    assert cam.bad_frames == 0
    assert cam.fps_measured() > 0


def test_read_latest_never_blocks(make_camera: Callable[..., OpenCVCamera], faults: FaultSwitch) -> None:
    cam = make_camera()
    fresh(cam)
    faults.inject("stall")  # the capture thread now sits in grab()
    worst = 0.0
    for _ in range(50):
        t0 = time.monotonic()
        with contextlib.suppress(RobotError):
            cam.read_latest(0.05)
        worst = max(worst, time.monotonic() - t0)
        time.sleep(0.005)
    assert worst < 0.02


def test_stall_is_stale_then_timeout(make_camera: Callable[..., OpenCVCamera], faults: FaultSwitch) -> None:
    cam = make_camera()
    fresh(cam)
    faults.inject("stall")
    err, took = first_error(cam, max_age=0.2, within=1.0)
    assert isinstance(err, StaleObservationError) and "old" in str(err)
    assert took < 0.2 + 0.15  # the newest frame is at most one period old when the stall starts
    assert wait_for(cam, DeviceTimeoutError, within=cam.read_timeout + 0.5) <= cam.read_timeout + 0.5
    assert not cam.is_connected


def test_disconnect_fault_raises_connection_error(
    make_camera: Callable[..., OpenCVCamera], faults: FaultSwitch
) -> None:
    cam = make_camera()
    fresh(cam)
    faults.inject("disconnect")
    assert wait_for(cam, DeviceConnectionError, within=2.0) < 1.0
    with pytest.raises(DeviceConnectionError, match="ended"):  # stays raised
        cam.read_latest(10.0)


def test_server_stop_raises_connection_error(
    make_camera: Callable[..., OpenCVCamera], server: MJPEGCameraServer
) -> None:
    cam = make_camera()
    fresh(cam)
    server.stop()
    assert wait_for(cam, DeviceConnectionError, within=2.0) < 1.0


def test_corrupt_frames_raise_protocol_error(make_camera: Callable[..., OpenCVCamera], faults: FaultSwitch) -> None:
    cam = make_camera()
    fresh(cam)
    faults.inject("corrupt")
    err, _ = first_error(cam, max_age=0.2, within=1.0)
    assert isinstance(err, StaleObservationError)  # broken parts are never handed out
    assert wait_for(cam, DeviceProtocolError, within=2.0) < 1.5


def test_occasional_corrupt_or_dropped_frames_are_skipped(
    make_camera: Callable[..., OpenCVCamera], faults: FaultSwitch, server: MJPEGCameraServer
) -> None:
    cam = make_camera()
    faults.inject("corrupt", rate=0.3)
    faults.inject("drop", rate=0.3)
    frame = frames_after(cam, 20)  # still flowing, with no stored error
    c = server.counts()
    # Withheld parts never reach the client; of those sent, the corrupt ones are skipped (counted in
    # bad_frames) and the rest handed out: sent = good + bad, up to the parts still in FFmpeg's buffer.
    assert c["withheld"] > 0 and c["corrupt"] > 0 and cam.bad_frames > 0
    assert c["sent"] - 3 <= frame.index + 1 + cam.bad_frames <= c["sent"], (c, frame.index, cam.bad_frames)
    assert cam.bad_frames <= c["corrupt"]


def test_drop_all_is_stale(make_camera: Callable[..., OpenCVCamera], faults: FaultSwitch) -> None:
    cam = make_camera()
    fresh(cam)
    faults.inject("drop")
    err, took = first_error(cam, max_age=0.2, within=1.0)
    assert isinstance(err, StaleObservationError) and took < 0.35


def test_reconnect_recovers(make_camera: Callable[..., OpenCVCamera], faults: FaultSwitch) -> None:
    cam = make_camera(reconnect=True)
    before = fresh(cam)
    faults.inject("disconnect")
    seen: set[type[RobotError]] = set()
    t0 = time.monotonic()
    while time.monotonic() - t0 < 0.6:  # while the server refuses us: stale, never a hard error
        try:
            cam.read_latest(0.1)
        except RobotError as e:
            seen.add(type(e))
        time.sleep(0.02)
    assert seen == {StaleObservationError}
    faults.clear()
    after = fresh(cam, within=3.0)  # backoff is capped at 2 s
    assert after.index > before.index and cam.reconnects >= 1


def test_unreachable_url_fails_fast() -> None:
    with socket.socket() as s:  # a port that was free a moment ago: nothing listens there
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    cam = OpenCVCamera("cam_x", f"http://127.0.0.1:{port}/cam_x.mjpg", connect_timeout=2.0)
    t0 = time.monotonic()
    with pytest.raises(DeviceConnectionError, match=f"127.0.0.1:{port}"):
        cam.connect()
    assert time.monotonic() - t0 < 1.0
    assert not cam.is_connected


def test_silent_stream_times_out_at_connect(server: MJPEGCameraServer, faults: FaultSwitch) -> None:
    faults.inject("stall")
    cam = OpenCVCamera("cam_high", server.url("cam_high"), connect_timeout=0.5)
    t0 = time.monotonic()
    with pytest.raises(DeviceTimeoutError, match=r"cam_high\.mjpg"):
        cam.connect()
    assert time.monotonic() - t0 < 0.5 + 0.5
    cam.disconnect()


def test_connection_guards(server: MJPEGCameraServer) -> None:
    cam = OpenCVCamera("cam_high", server.url("cam_high"))
    with pytest.raises(DeviceNotConnectedError):
        cam.read_latest()
    with cam:
        with pytest.raises(DeviceAlreadyConnectedError):
            cam.connect()
        fresh(cam)
    assert not cam.is_connected
    t0 = time.monotonic()
    cam.disconnect()  # idempotent
    assert time.monotonic() - t0 < 0.1
    with pytest.raises(DeviceNotConnectedError):
        cam.read_latest()
    cam.connect()  # and reconnectable
    assert fresh(cam).index >= 0
    cam.disconnect()


def test_bad_arguments() -> None:
    with pytest.raises(ValueError, match="timeouts"):
        OpenCVCamera("c", 0, connect_timeout=0)
    with pytest.raises(ValueError, match="resize_to"):
        OpenCVCamera("c", 0, resize_to=(0, 10))


def test_file_source_ends_with_connection_error(tmp_path: Path) -> None:
    # A non-URL source goes through OpenCV's default backend (as a device index would); a finite file
    # is a stream that ends, at decode speed, so the end may already be seen inside connect().
    path = tmp_path / "clip.avi"
    writer = cv2.VideoWriter(str(path), cv2.VideoWriter.fourcc(*"MJPG"), 10.0, (32, 24))
    for _ in range(5):
        writer.write(np.zeros((24, 32, 3), np.uint8))
    writer.release()
    cam = OpenCVCamera("clip", str(path), connect_timeout=2.0)
    try:
        cam.connect()
        assert wait_for(cam, DeviceConnectionError, within=1.0) < 1.0
    except DeviceConnectionError as e:
        assert "ended" in str(e)
    finally:
        cam.disconnect()
    missing = OpenCVCamera("clip", str(tmp_path / "missing.avi"))
    with pytest.raises(DeviceConnectionError, match="could not open"):
        missing.connect()
