"""The fake MJPEG camera server, read with a raw socket: framing, content, faults, shutdown bounds."""

from __future__ import annotations

import socket
import time
import urllib.error
import urllib.request
from collections.abc import Iterator

import cv2
import numpy as np
import pytest
from numpy.typing import NDArray

from hw_drivers.fakes.backend import KinematicBackend
from hw_drivers.fakes.faults import FaultSwitch
from hw_drivers.fakes.mjpeg_camera import BOUNDARY, MJPEGCameraServer

FPS = 30.0


@pytest.fixture
def faults() -> FaultSwitch:
    return FaultSwitch()


@pytest.fixture
def server(faults: FaultSwitch) -> Iterator[MJPEGCameraServer]:
    backend = KinematicBackend(image_size=(64, 48))
    with MJPEGCameraServer(backend, fps=FPS, faults=faults) as srv:
        yield srv
    backend.close()


class Stream:
    """A minimal multipart reader over a raw socket (so the test does not depend on the driver)."""

    def __init__(self, srv: MJPEGCameraServer, camera: str = "cam_high", timeout: float = 1.0) -> None:
        self.sock = socket.create_connection(("127.0.0.1", srv.port), timeout=timeout)
        self.sock.sendall(f"GET /{camera}.mjpg HTTP/1.0\r\nHost: x\r\n\r\n".encode())
        self.f = self.sock.makefile("rb")

    def headers(self) -> list[bytes]:
        lines = []
        while (line := self.f.readline()) not in (b"\r\n", b""):
            lines.append(line.strip())
        return lines

    def part(self) -> bytes:
        boundary = self.f.readline()
        if boundary == b"":
            raise EOFError
        assert boundary.strip() == f"--{BOUNDARY}".encode()
        length = next(int(h.split(b":")[1]) for h in self.headers() if h.lower().startswith(b"content-length"))
        body = self.f.read(length)
        assert self.f.read(2) == b"\r\n"
        return body

    def close(self) -> None:
        self.f.close()
        self.sock.close()


def decode(jpeg: bytes) -> NDArray[np.uint8] | None:
    bgr = cv2.imdecode(np.frombuffer(jpeg, np.uint8), cv2.IMREAD_COLOR)
    return None if bgr is None else np.asarray(cv2.cvtColor(bgr, cv2.COLOR_BGR2RGB), dtype=np.uint8)


def check_gradients(rgb: NDArray[np.uint8], blue: int) -> None:
    # KinematicBackend: R rises 0→255 left→right, G top→bottom, B constant per camera.
    r, g, b = (rgb[..., c].astype(int) for c in range(3))
    assert abs(r[:, 0].mean() - 0) < 12 and abs(r[:, -1].mean() - 255) < 12
    assert abs(g[0].mean() - 0) < 12 and abs(g[-1].mean() - 255) < 12
    assert abs(b.mean() - blue) < 12


def test_index_snapshot_and_404(server: MJPEGCameraServer) -> None:
    index = urllib.request.urlopen(f"http://127.0.0.1:{server.port}/", timeout=2).read().decode()
    for cam in server.backend.cameras:
        assert f"/{cam}.mjpg" in index and f"/{cam}.jpg" in index
    with urllib.request.urlopen(server.url("cam_left_wrist", snapshot=True), timeout=2) as resp:
        assert resp.headers["Content-Type"] == "image/jpeg"
        img = decode(resp.read())
    assert img is not None and img.shape == (48, 64, 3)
    check_gradients(img, blue=127 + 40)
    with pytest.raises(urllib.error.HTTPError) as info:
        urllib.request.urlopen(f"http://127.0.0.1:{server.port}/nope.mjpg", timeout=2)
    assert info.value.code == 404


def test_stream_framing_content_and_rate(server: MJPEGCameraServer) -> None:
    s = Stream(server)
    try:
        head = s.headers()
        assert head[0].startswith(b"HTTP/1.0 200")
        assert f"Content-Type: multipart/x-mixed-replace; boundary={BOUNDARY}".encode() in head
        first = decode(s.part())
        assert first is not None
        check_gradients(first, blue=127)
        # Counts, not a rate (the rate is `pilworld bench drivers`' camera_fps): every part the server
        # sent arrives, whole and decodable, in order of sending.
        parts = [s.part() for _ in range(20)]
        assert all(decode(p) is not None for p in parts)
        c = server.counts()
        assert c["withheld"] == c["corrupt"] == 0
        assert 21 <= c["sent"] <= 23  # the first part, these 20, and at most two still in flight
    finally:
        s.close()


def test_url_and_host_checks(faults: FaultSwitch) -> None:
    backend = KinematicBackend()
    with pytest.raises(ValueError, match="loopback"):
        MJPEGCameraServer(backend, host="0.0.0.0")
    srv = MJPEGCameraServer(backend, host="localhost")
    with pytest.raises(RuntimeError, match="not started"):
        srv.url("cam_high")
    with srv:
        assert srv.url("cam_high").endswith("/cam_high.mjpg")
        with pytest.raises(ValueError, match="camera"):
            srv.url("nope")


def test_stall_keeps_connection_open_but_silent(server: MJPEGCameraServer, faults: FaultSwitch) -> None:
    s = Stream(server, timeout=0.5)
    try:
        s.headers()
        s.part()
        faults.inject("stall")
        time.sleep(2 / FPS)  # let a part already on its way arrive
        s.sock.settimeout(0.0)
        try:  # drain whatever was in flight
            while s.sock.recv(65536):
                pass
        except BlockingIOError:
            pass
        s.sock.settimeout(0.5)
        with pytest.raises(TimeoutError):  # silent, not closed (a close would read b"")
            s.sock.recv(1)
        faults.clear()
        assert s.sock.recv(1)  # and it resumes
    finally:
        s.close()


def test_disconnect_drops_clients_and_refuses_new(server: MJPEGCameraServer, faults: FaultSwitch) -> None:
    s = Stream(server)
    try:
        s.headers()
        s.part()
        faults.inject("stall")  # a silent stream must be dropped too (the watcher thread)
        time.sleep(0.1)
        faults.inject("disconnect")
        t0 = time.monotonic()
        with pytest.raises(EOFError):
            for _ in range(10):
                s.part()
        assert time.monotonic() - t0 < 0.5
    finally:
        s.close()
    s2 = Stream(server)
    try:
        assert s2.f.read() == b""  # closed without a response
    finally:
        s2.close()
    faults.clear()
    s3 = Stream(server)
    try:
        s3.headers()
        assert decode(s3.part()) is not None
    finally:
        s3.close()


def test_corrupt_parts_do_not_decode(server: MJPEGCameraServer, faults: FaultSwitch) -> None:
    faults.inject("corrupt")
    s = Stream(server)
    try:
        s.headers()
        for _ in range(3):
            part = s.part()
            assert part[:2] == b"\xff\xd8"  # still looks like a JPEG
            assert decode(part) is None
    finally:
        s.close()


def test_drop_skips_frames_at_rate(server: MJPEGCameraServer, faults: FaultSwitch) -> None:
    faults.inject("drop", rate=0.5)
    s = Stream(server)
    try:
        s.headers()
        n = 40
        for _ in range(n):
            s.part()
        c = server.counts()
        # Every withheld period sends nothing, every other one sends exactly one part; at rate 0.5 the
        # withheld share of ≥ 40 sent parts lies well inside [0.25, 0.75] (binomial, p < 1e-3 outside).
        assert n <= c["sent"] <= n + 2 and c["periods"] == c["sent"] + c["withheld"]
        assert 0.25 <= c["withheld"] / c["periods"] <= 0.75, c
    finally:
        s.close()


def test_stop_closes_clients_quickly(faults: FaultSwitch) -> None:
    srv = MJPEGCameraServer(KinematicBackend(image_size=(32, 32)), fps=FPS, faults=faults).start()
    streams = [Stream(srv), Stream(srv, "cam_right_wrist")]
    faults.inject("stall")  # one silent, one… also silent: stop must not wait for a send to fail
    try:
        for s in streams:
            s.headers()
        t0 = time.monotonic()
        srv.stop()
        assert time.monotonic() - t0 < 1.0
        for s in streams:
            assert s.f.read() is not None  # returns (EOF) instead of timing out
        srv.stop()  # idempotent
    finally:
        for s in streams:
            s.close()
