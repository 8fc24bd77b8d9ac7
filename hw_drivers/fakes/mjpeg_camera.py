"""A fake IP camera: MJPEG over HTTP, one stream per camera of a :class:`RigBackend`.

IP cameras (and ``mjpg-streamer``, ``ustreamer``, OctoPrint webcams) serve
``multipart/x-mixed-replace`` — an endless HTTP response whose parts are JPEG images. This server does
the same on loopback so :class:`hw_drivers.cameras.opencv.OpenCVCamera` runs against a real HTTP stream:

* ``/<camera>.mjpg`` — the stream, at ``fps``;
* ``/<camera>.jpg``  — one snapshot;
* ``/``              — an HTML index of the streams.

Faults (``faults.inject(kind)``), checked before every part:

* ``stall``      — nothing more is sent; the connection stays open (a frozen camera);
* ``disconnect`` — open stream connections are closed and new ones are closed on accept, while active;
* ``corrupt``    — a part carries a broken JPEG (header kept, body scrambled, length right), at ``rate``;
* ``drop``       — a frame is skipped (nothing sent in its period), at ``rate``.

:meth:`counts` says how many parts were decided, sent, withheld and corrupted, so tests assert counts
(every part sent is received, a drop rate withholds its share) instead of timing the stream; the
streaming rate itself is a ``pilworld bench drivers`` figure.
"""

from __future__ import annotations

import collections
import contextlib
import html
import socket
import threading
import time
from http.server import BaseHTTPRequestHandler, ThreadingHTTPServer
from types import TracebackType
from typing import Any

import cv2
import numpy as np
from numpy.typing import NDArray

from hw_drivers.fakes.backend import RigBackend
from hw_drivers.fakes.faults import FaultSwitch
from pilworld.config.network import is_loopback

BOUNDARY = "pilworldframe"
_STOP_JOIN_S = 2.0  # bound on stop(): handler threads get this long to notice the closed sockets


def encode_jpeg(rgb: NDArray[np.uint8], quality: int) -> bytes:
    # The backend hands out RGB; JPEG encoders in OpenCV expect BGR (and decoders return BGR).
    ok, buf = cv2.imencode(".jpg", cv2.cvtColor(rgb, cv2.COLOR_RGB2BGR), [cv2.IMWRITE_JPEG_QUALITY, quality])
    if not ok:
        raise RuntimeError("cv2.imencode failed")
    return bytes(buf.tobytes())


def corrupt_jpeg(jpeg: bytes) -> bytes:
    """Keep the SOI marker and headers, scramble the entropy-coded body and cut the EOI: undecodable."""
    cut = min(len(jpeg), 160)
    body = bytes(np.random.default_rng(len(jpeg)).integers(0, 256, len(jpeg) - cut, dtype=np.uint8))
    return jpeg[:cut] + body[: max(0, len(body) - 2)]


class _Server(ThreadingHTTPServer):
    daemon_threads = True
    owner: MJPEGCameraServer

    def verify_request(self, request: Any, client_address: Any) -> bool:
        # `disconnect` refuses new clients: the socket is closed before any byte is read or written.
        return not self.owner.faults.active("disconnect")


class _Handler(BaseHTTPRequestHandler):
    server: _Server
    protocol_version = "HTTP/1.0"  # the stream ends when the connection does; no chunking
    timeout = 5.0  # a client that stops reading cannot pin a handler thread forever

    def log_message(self, format: str, *args: Any) -> None:  # quiet: tests run many requests
        pass

    def do_GET(self) -> None:
        owner = self.server.owner
        path = self.path.split("?", 1)[0].lstrip("/")
        if path in ("", "index.html"):
            self._send_body(200, "text/html; charset=utf-8", owner.index_html().encode())
            return
        name, _, ext = path.rpartition(".")
        if name not in owner.backend.cameras or ext not in ("mjpg", "jpg"):
            self._send_body(404, "text/plain", f"no such stream: /{path}\n".encode())
            return
        owner._track(self.connection, add=True)
        try:
            if ext == "jpg":
                self._snapshot(owner, name)
            else:
                self._stream(owner, name)
        except OSError:
            pass  # the client went away, or stop()/disconnect closed the socket under us
        finally:
            owner._track(self.connection, add=False)

    def _send_body(self, code: int, ctype: str, body: bytes) -> None:
        self.send_response(code)
        self.send_header("Content-Type", ctype)
        self.send_header("Content-Length", str(len(body)))
        self.send_header("Cache-Control", "no-cache")
        self.end_headers()
        self.wfile.write(body)

    def _snapshot(self, owner: MJPEGCameraServer, camera: str) -> None:
        jpeg = owner._next_part(camera)
        while jpeg is None and not owner._stopping.is_set():  # stalled/dropped: the request hangs
            if owner.faults.active("disconnect"):
                return
            time.sleep(owner.period)
            jpeg = owner._next_part(camera)
        if jpeg is not None:
            self._send_body(200, "image/jpeg", jpeg)

    def _stream(self, owner: MJPEGCameraServer, camera: str) -> None:
        self.send_response(200)
        self.send_header("Content-Type", f"multipart/x-mixed-replace; boundary={BOUNDARY}")
        self.send_header("Cache-Control", "no-cache, no-store")
        self.send_header("Pragma", "no-cache")
        self.end_headers()
        next_t = time.monotonic()
        while not owner._stopping.is_set():
            if owner.faults.active("disconnect"):
                return  # do_GET's caller closes the socket: the client reads EOF
            jpeg = owner._next_part(camera)
            if jpeg is not None:
                head = f"--{BOUNDARY}\r\nContent-Type: image/jpeg\r\nContent-Length: {len(jpeg)}\r\n\r\n"
                self.wfile.write(head.encode() + jpeg + b"\r\n")
                self.wfile.flush()
            next_t += owner.period
            delay = next_t - time.monotonic()
            if delay < -owner.period:  # fell behind (slow client or CPU): don't burst to catch up
                next_t = time.monotonic()
            elif delay > 0:
                owner._stopping.wait(delay)


class MJPEGCameraServer:
    """MJPEG-over-HTTP streams of ``backend.cameras`` (see the module docstring).

    ``port=0`` picks a free port (read it from :attr:`port` or :meth:`url` after :meth:`start`).
    Only loopback hosts unless ``allow_remote=True``: a fake camera has no business on a network.
    """

    def __init__(
        self,
        backend: RigBackend,
        *,
        host: str = "127.0.0.1",
        port: int = 0,
        fps: float = 15.0,
        quality: int = 90,
        faults: FaultSwitch | None = None,
        allow_remote: bool = False,
    ) -> None:
        if not allow_remote and not is_loopback(host):
            raise ValueError(f"host: {host!r} is not a loopback address (pass allow_remote=True to serve it)")
        if not fps > 0:
            raise ValueError(f"fps: expected > 0, got {fps}")
        if not 1 <= quality <= 100:
            raise ValueError(f"quality: expected 1 … 100, got {quality}")
        self.backend = backend
        self.host = host
        self._port = port
        self.fps = float(fps)
        self.period = 1.0 / self.fps
        self.quality = int(quality)
        self.faults = faults if faults is not None else FaultSwitch()
        self._server: _Server | None = None
        self._thread: threading.Thread | None = None
        self._stopping = threading.Event()
        self._clients: set[socket.socket] = set()
        self._lock = threading.Lock()
        self._watch: threading.Thread | None = None
        self._counts: collections.Counter[str] = collections.Counter()

    @property
    def port(self) -> int:
        if self._server is None:
            raise RuntimeError("server not started")
        return int(self._server.server_address[1])

    def url(self, camera: str, *, snapshot: bool = False) -> str:
        if camera not in self.backend.cameras:
            raise ValueError(f"camera: expected one of {self.backend.cameras}, got {camera!r}")
        return f"http://{self.host}:{self.port}/{camera}.{'jpg' if snapshot else 'mjpg'}"

    def index_html(self) -> str:
        rows = "".join(
            f'<li><a href="/{html.escape(c)}.mjpg">{html.escape(c)}</a> '
            f'(<a href="/{html.escape(c)}.jpg">snapshot</a>)</li>'
            for c in self.backend.cameras
        )
        return f"<!doctype html><title>PiL-World fake cameras</title><ul>{rows}</ul>\n"

    def start(self) -> MJPEGCameraServer:
        if self._server is not None:
            raise RuntimeError("server already started")
        self._stopping.clear()
        server = _Server((self.host, self._port), _Handler)
        server.owner = self
        self._server = server
        self._thread = threading.Thread(
            target=server.serve_forever, kwargs={"poll_interval": 0.05}, name="mjpeg-server", daemon=True
        )
        self._thread.start()
        # A stalled handler sends nothing, so it only notices `disconnect` when it next wakes; this
        # watcher closes every open stream as soon as the fault is switched on (bounded by its poll).
        self._watch = threading.Thread(target=self._watch_faults, name="mjpeg-faults", daemon=True)
        self._watch.start()
        return self

    def stop(self) -> None:
        """Stop serving and close every client connection; returns within a few seconds at most."""
        server, self._server = self._server, None
        if server is None:
            return
        self._stopping.set()
        server.shutdown()  # returns once serve_forever has seen the flag (its poll interval)
        self._close_clients()
        server.server_close()
        deadline = time.monotonic() + _STOP_JOIN_S
        for t in (self._thread, self._watch):
            if t is not None:
                t.join(max(0.0, deadline - time.monotonic()))
        self._thread = self._watch = None

    def __enter__(self) -> MJPEGCameraServer:
        return self.start()

    def __exit__(
        self, exc_type: type[BaseException] | None, exc: BaseException | None, tb: TracebackType | None
    ) -> None:
        self.stop()

    # -- internals shared with the handlers

    def counts(self) -> dict[str, int]:
        """Parts decided so far over every stream and snapshot: ``periods`` (parts due), ``sent``
        (handed to a connection, corrupt ones included), ``withheld`` (stall/drop) and ``corrupt``."""
        with self._lock:
            return {k: self._counts[k] for k in ("periods", "sent", "withheld", "corrupt")}

    def _count(self, *keys: str) -> None:
        with self._lock:
            self._counts.update(keys)

    def _next_part(self, camera: str) -> bytes | None:
        """The JPEG to send for this period, or None when a fault says send nothing."""
        if self.faults.active("stall") or self.faults.active("drop"):
            self._count("periods", "withheld")
            return None
        image, _ = self.backend.frame(camera)
        jpeg = encode_jpeg(image, self.quality)
        if self.faults.active("corrupt"):
            self._count("periods", "sent", "corrupt")
            return corrupt_jpeg(jpeg)
        self._count("periods", "sent")
        return jpeg

    def _track(self, conn: socket.socket, *, add: bool) -> None:
        with self._lock:
            if add:
                self._clients.add(conn)
            else:
                self._clients.discard(conn)

    def _close_clients(self) -> None:
        with self._lock:
            clients = list(self._clients)
            self._clients.clear()
        for conn in clients:
            # shutdown() wakes a handler blocked in send() and makes the client read EOF at once;
            # the handler's own close() follows when its thread unwinds.
            with contextlib.suppress(OSError):
                conn.shutdown(socket.SHUT_RDWR)

    def _watch_faults(self) -> None:
        while not self._stopping.wait(0.05):
            if self.faults.active("disconnect"):
                self._close_clients()
