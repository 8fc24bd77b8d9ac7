"""``OpenCVCamera``: a :class:`~hw_drivers.cameras.base.Camera` on ``cv2.VideoCapture``.

One background thread owns the ``VideoCapture`` from open to release (OpenCV captures are not safe to
release from another thread while ``grab()`` blocks in it). It grabs continuously, stamps each frame
with ``time.monotonic()`` as soon as ``grab()`` returns (the receipt time, before decoding), converts
BGR → RGB and optionally resizes with area interpolation. :meth:`OpenCVCamera.read_latest` only looks
at the newest frame under a lock, so it never waits for the device.

Sources: a device index (V4L2 on Linux) or a stream URL. URLs are opened with FFmpeg (``CAP_FFMPEG``);
the opencv-python wheel in this venv (4.14, FFmpeg 62.x) reads MJPEG over HTTP
(``multipart/x-mixed-replace``) directly, and honours ``CAP_PROP_OPEN_TIMEOUT_MSEC`` /
``CAP_PROP_READ_TIMEOUT_MSEC``, so a silent stream cannot block the thread forever.

``VideoCapture`` reports every failure as ``False``; the thread tells them apart by timing:

* ``grab()`` fails after about ``read_timeout`` → the stream went silent → ``DeviceTimeoutError``;
* ``grab()`` fails at once, several times in a row → the stream ended or the device was unplugged →
  ``DeviceConnectionError``;
* a part arrives but does not decode (``grab`` or ``retrieve`` fails after waiting for data) → skipped;
  ``_MAX_BAD_FRAMES`` in a row → ``DeviceProtocolError``.

The error is stored and raised by every later :meth:`read_latest` — unless ``reconnect=True``, when the
thread reopens the source with exponential backoff and :meth:`read_latest` raises
``StaleObservationError`` (the newest frame grows old) until frames flow again.
"""

from __future__ import annotations

import collections
import threading
import time
from types import TracebackType
from typing import Any

import cv2
import numpy as np
from numpy.typing import NDArray

from hw_drivers.cameras.base import Frame
from hw_drivers.errors import (
    DeviceAlreadyConnectedError,
    DeviceConnectionError,
    DeviceNotConnectedError,
    DeviceProtocolError,
    DeviceTimeoutError,
    RobotError,
    StaleObservationError,
)

_FAST_FAIL_S = 0.005  # a grab() that fails quicker than this read no data: the stream is gone
_MAX_FAST_FAILS = 3  # … this many times in a row (one can be a hiccup at a reconnect)
_MAX_BAD_FRAMES = 10  # undecodable parts in a row before the stream is declared broken
_JOIN_S = 3.0  # bound on disconnect(): a grab() blocked in FFmpeg returns within read_timeout
_BACKOFF_S = (0.1, 2.0)  # reconnect backoff: first wait, cap (doubling in between)
_FPS_WINDOW_S = 3.0


class OpenCVCamera:
    """A camera on ``cv2.VideoCapture`` (see the module docstring).

    ``source``: a device index or a URL/path. ``width``/``height``/``fps`` are requested from a device
    (ignored by streams, which send what they send). ``resize_to=(width, height)`` resizes every frame.
    ``connect_timeout`` bounds :meth:`connect` (open + first frame); ``read_timeout`` is how long a
    silent stream is tolerated before ``DeviceTimeoutError``. ``backend_api``: a ``cv2.CAP_*`` to
    force (default: FFmpeg for URLs, OpenCV's choice for devices).
    """

    def __init__(
        self,
        name: str,
        source: int | str,
        *,
        width: int | None = None,
        height: int | None = None,
        fps: float | None = None,
        resize_to: tuple[int, int] | None = None,
        connect_timeout: float = 5.0,
        read_timeout: float = 2.0,
        reconnect: bool = False,
        backend_api: int | None = None,
    ) -> None:
        if connect_timeout <= 0 or read_timeout <= 0:
            raise ValueError(f"timeouts must be > 0, got connect {connect_timeout}, read {read_timeout}")
        if resize_to is not None and (len(resize_to) != 2 or min(resize_to) <= 0):
            raise ValueError(f"resize_to: expected (width, height) > 0, got {resize_to!r}")
        self._name = name
        self.source = source
        self._props = {cv2.CAP_PROP_FRAME_WIDTH: width, cv2.CAP_PROP_FRAME_HEIGHT: height, cv2.CAP_PROP_FPS: fps}
        self._resize = resize_to
        self.connect_timeout = float(connect_timeout)
        self.read_timeout = float(read_timeout)
        self.reconnect = reconnect
        self._api = backend_api if backend_api is not None else self._default_api(source)
        self._lock = threading.Lock()
        self._latest: Frame | None = None
        self._stamps: collections.deque[float] = collections.deque(maxlen=4096)
        self._error: RobotError | None = None
        self._first = threading.Event()  # set on the first frame, or on a failure before it
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        self._connected = False
        self._t_connect = 0.0
        self.reconnects = 0  # reopened after a failure (reconnect=True)
        self.bad_frames = 0  # undecodable parts skipped

    @staticmethod
    def _default_api(source: int | str) -> int:
        if isinstance(source, str) and "://" in source:
            return int(cv2.CAP_FFMPEG)
        return int(cv2.CAP_ANY)

    # -- the Camera contract

    @property
    def name(self) -> str:
        return self._name

    @property
    def is_connected(self) -> bool:
        return self._connected and self._error is None

    def connect(self) -> None:
        """Open the source in the capture thread and wait for its first frame (``connect_timeout``)."""
        if self._connected:
            raise DeviceAlreadyConnectedError(self._name, "camera already connected")
        # A fresh stop event per connection: a thread left behind by a timed-out connect() (blocked
        # in the device) keeps its own, already set, and never touches the new connection's state.
        self._stop = threading.Event()
        self._first = threading.Event()
        self._latest, self._error = None, None
        self._stamps.clear()
        self._t_connect = time.monotonic()
        self._thread = threading.Thread(
            target=self._run, args=(self._stop, self._first), name=f"camera-{self._name}", daemon=True
        )
        self._thread.start()
        if not self._first.wait(self.connect_timeout):
            self._shutdown(join=0.2)  # don't stretch connect() past its bound; the thread cleans up
            raise DeviceTimeoutError(self._name, f"no frame from {self.source!r} within {self.connect_timeout} s")
        error = self._stored_error()
        if error is not None:
            self._shutdown(join=0.2)
            raise error
        self._connected = True

    def disconnect(self) -> None:
        """Stop the capture thread (joined for at most ``_JOIN_S``) and release the source. Idempotent."""
        self._connected = False
        self._shutdown(join=_JOIN_S)

    def read_latest(self, max_age: float = 0.2) -> Frame:
        """The newest frame, or ``StaleObservationError`` if it is older than ``max_age`` seconds.

        Raises the stored error when the stream ended or broke (without ``reconnect``). Never blocks on
        the device: it takes a lock the capture thread holds only to swap in a new frame.
        """
        if not self._connected:
            raise DeviceNotConnectedError(self._name, "camera not connected (call connect())")
        with self._lock:
            frame, error = self._latest, self._error
        if error is not None:
            # The same stored error is raised on every call: drop the previous traceback so it does
            # not grow by one entry per call in a polling loop.
            raise error.with_traceback(None)
        if frame is None:  # unreachable after a successful connect(); kept for the type checker
            raise StaleObservationError(self._name, "no frame yet")
        age = time.monotonic() - frame.timestamp
        if age > max_age:
            raise StaleObservationError(
                self._name, f"newest frame #{frame.index} is {age:.3f} s old (max_age {max_age} s)"
            )
        return frame

    def fps_measured(self) -> float:
        """Frames received per second over the last few seconds (0 when nothing arrives)."""
        now = time.monotonic()
        span = min(_FPS_WINDOW_S, now - self._t_connect)
        if span <= 0:
            return 0.0
        with self._lock:
            n = sum(1 for t in self._stamps if t >= now - span)
        return n / span

    def __enter__(self) -> OpenCVCamera:
        self.connect()
        return self

    def __exit__(
        self, exc_type: type[BaseException] | None, exc: BaseException | None, tb: TracebackType | None
    ) -> None:
        self.disconnect()

    # -- the capture thread

    def _stored_error(self) -> RobotError | None:
        with self._lock:
            return self._error

    def _shutdown(self, join: float) -> None:
        self._stop.set()
        thread, self._thread = self._thread, None
        if thread is not None and thread is not threading.current_thread():
            thread.join(join)

    def _fail(self, error: RobotError, stop: threading.Event, first: threading.Event) -> None:
        with self._lock:
            if self._error is None and not stop.is_set():
                self._error = error
        first.set()  # wakes connect() if it is still waiting

    def _open(self) -> cv2.VideoCapture | None:
        params: list[int] = []
        if self._api == cv2.CAP_FFMPEG:
            # Both bounds are enforced by FFmpeg's interrupt callback inside OpenCV.
            params = [
                cv2.CAP_PROP_OPEN_TIMEOUT_MSEC,
                int(self.connect_timeout * 1000),
                cv2.CAP_PROP_READ_TIMEOUT_MSEC,
                int(self.read_timeout * 1000),
            ]
        cap = cv2.VideoCapture(self.source, self._api, params)
        if not cap.isOpened():
            cap.release()
            return None
        if isinstance(self.source, int):
            for prop, value in self._props.items():
                if value is not None:
                    cap.set(prop, float(value))
        return cap

    def _publish(self, bgr: NDArray[Any], stamp: float, stop: threading.Event, first: threading.Event) -> None:
        if self._resize is not None and (bgr.shape[1], bgr.shape[0]) != self._resize:
            bgr = cv2.resize(bgr, self._resize, interpolation=cv2.INTER_AREA)
        code = cv2.COLOR_GRAY2RGB if bgr.ndim == 2 else cv2.COLOR_BGR2RGB
        rgb = np.ascontiguousarray(cv2.cvtColor(bgr, code), dtype=np.uint8)
        with self._lock:
            if stop.is_set():
                return
            index = 0 if self._latest is None else self._latest.index + 1
            self._latest = Frame(image=rgb, timestamp=stamp, index=index)
            self._stamps.append(stamp)
        first.set()

    def _run(self, stop: threading.Event, first: threading.Event) -> None:
        cap: cv2.VideoCapture | None = None
        backoff = _BACKOFF_S[0]
        try:
            while not stop.is_set():
                if cap is None:
                    cap = self._open()
                    if cap is None:
                        failed = DeviceConnectionError(self._name, f"could not open {self.source!r}")
                        if not self._retry(failed, backoff, stop, first):
                            return
                        backoff = min(2 * backoff, _BACKOFF_S[1])
                        continue
                err = self._capture(cap, stop, first)  # returns when the stream failed (or on stop)
                cap.release()
                cap = None
                if err is None or not self._retry(err, backoff, stop, first):
                    return
                backoff = min(2 * backoff, _BACKOFF_S[1])
        except Exception as e:  # an OpenCV exception: report it typed, never die silently
            self._fail(DeviceConnectionError(self._name, f"capture from {self.source!r} failed: {e!r}"), stop, first)
        finally:
            if cap is not None:
                cap.release()

    def _retry(self, err: RobotError, backoff: float, stop: threading.Event, first: threading.Event) -> bool:
        """Store ``err`` (→ False), or wait ``backoff`` to reconnect (→ True) once frames have flowed."""
        # Before the first frame a failure is final: a wrong URL or a missing device should fail
        # connect() fast rather than be retried until connect_timeout.
        if not self.reconnect or not first.is_set() or self._error is not None:
            self._fail(err, stop, first)
            return False
        self.reconnects += 1
        return not stop.wait(backoff)

    def _capture(self, cap: cv2.VideoCapture, stop: threading.Event, first: threading.Event) -> RobotError | None:
        fast = bad = 0
        while not stop.is_set():
            t0 = time.monotonic()
            ok = cap.grab()
            stamp = time.monotonic()
            if ok:
                ok, bgr = cap.retrieve()
                if ok and bgr is not None and bgr.size:
                    self._publish(bgr, stamp, stop, first)
                    fast = bad = 0
                    continue
            waited = stamp - t0
            if not ok and waited >= 0.9 * self.read_timeout:
                return DeviceTimeoutError(self._name, f"no frame from {self.source!r} for {waited:.1f} s")
            if waited < _FAST_FAIL_S:
                fast += 1
                if fast >= _MAX_FAST_FAILS:
                    return DeviceConnectionError(self._name, f"stream {self.source!r} ended (or the device is gone)")
                continue
            fast = 0
            bad += 1
            self.bad_frames += 1
            if bad >= _MAX_BAD_FRAMES:
                return DeviceProtocolError(self._name, f"{bad} frames in a row from {self.source!r} did not decode")
        return None
