"""``OpenPiClient``: a :class:`~pilworld.policies.base.Policy` backed by an openpi websocket policy server.

The protocol is openpi's (Physical-Intelligence/openpi, ``packages/openpi-client/src/openpi_client/
websocket_client_policy.py`` and ``src/openpi/serving/websocket_policy_server.py``):

1. connect; the server sends one binary msgpack frame of metadata (any dict, often empty);
2. per query: send the packed observation (:func:`~pilworld.policies.openpi.wire.observation_to_openpi`),
   receive one binary frame ``{"actions": [H, D], "server_timing": {"infer_ms", "prev_total_ms"}}``;
3. on a server exception: one *text* frame with the traceback, then a close with code 1011;
4. ``GET /healthz`` on the same port answers 200.

Unlike openpi's client (which waits for a server forever and has no timeouts) this one fails fast with
typed errors, validates every reply and never reconnects silently: after a timeout or a dropped
connection every further call raises :class:`PolicyConnectionError` until a new client is made.
Not thread-safe: one closed loop drives one client.
"""

from __future__ import annotations

import contextlib
import http.client
import time
from dataclasses import dataclass
from types import TracebackType
from typing import Any
from urllib.parse import urlsplit

import numpy as np
import websockets
from numpy.typing import NDArray
from websockets.sync.client import ClientConnection, connect

from pilworld.policies.base import PolicyError, validate_chunk
from pilworld.policies.openpi.errors import PolicyConnectionError, PolicyServerError, PolicyTimeoutError
from pilworld.policies.openpi.wire import (
    DEFAULT_IMAGE_SIZE,
    PILWORLD_KEY,
    RESET_KEY,
    observation_to_openpi,
    packb,
    parse_image_size,
    unpackb,
)
from pilworld.types import Observation


@dataclass(frozen=True)
class ChunkTiming:
    """Latency of one chunk."""

    client_ms: float  # round trip seen by the client: request sent → reply received (excl. encode/decode)
    server_infer_ms: float | None  # the server's policy inference (reply's server_timing.infer_ms)
    server_prev_total_ms: float | None  # the server's previous whole cycle incl. sending (prev_total_ms)


def websocket_url(host_or_url: str, port: int | None = None) -> str:
    """``ws://host:port`` from a host and port, or a ``ws://``/``wss://`` URL (port appended like openpi)."""
    if not isinstance(host_or_url, str) or not host_or_url:
        raise ValueError(f"--checkpoints: expected a host name or a ws:// URL, got {host_or_url!r}")
    if host_or_url.startswith(("ws://", "wss://")):
        url = host_or_url
    elif "://" in host_or_url:
        raise ValueError(f"--checkpoints: expected a ws:// or wss:// URL, got {host_or_url!r}")
    else:
        url = f"ws://{host_or_url}"
    if port is not None:
        if isinstance(port, bool) or not isinstance(port, int) or not 0 < port < 65536:
            raise ValueError(f"port: expected 1..65535, got {port!r}")
        if urlsplit(url).port is not None:
            raise ValueError(f"port: {url} already names a port, got port={port} as well")
        url = f"{url.rstrip('/')}:{port}"
    try:
        urlsplit(url).port  # noqa: B018 - raises on a malformed port
    except ValueError as err:
        raise ValueError(f"--checkpoints: {url}: {err}") from None
    return url


def healthz(url: str, timeout: float = 2.0) -> bool:
    """True if ``GET /healthz`` on the websocket server at ``url`` answers 200 (openpi's health check)."""
    parts = urlsplit(url)
    host = parts.hostname or "127.0.0.1"
    secure = parts.scheme == "wss"
    port = parts.port or (443 if secure else 80)
    cls = http.client.HTTPSConnection if secure else http.client.HTTPConnection
    conn = cls(host, port, timeout=timeout)
    try:
        conn.request("GET", "/healthz")
        return conn.getresponse().status == 200
    except (OSError, http.client.HTTPException):
        return False
    finally:
        conn.close()


def _close_description(err: websockets.ConnectionClosed) -> str:
    frame = err.rcvd or err.sent
    if frame is None:
        return "without a close frame"
    return f"with code {int(frame.code)}" + (f" ({frame.reason})" if frame.reason else "")


def _number(value: Any) -> float | None:
    return float(value) if isinstance(value, int | float | np.number) and not isinstance(value, bool) else None


class OpenPiClient:
    """A remote policy speaking openpi's websocket protocol; connects (and reads metadata) on creation.

    ``image_size`` (int or (height, width)): what images are resized-with-padding to; by default the
    server's metadata ``image_size`` if it has one (our server does), else openpi's 224×224.
    ``horizon`` / ``action_dim``: the chunk shape replies must have (``None`` horizon = any);
    ``min_horizon``: the fewest steps a reply may have (the closed loop executes K·Δ of them).
    """

    def __init__(
        self,
        url: str = "ws://127.0.0.1:8000",
        port: int | None = None,
        *,
        connect_timeout: float = 10.0,
        reply_timeout: float = 30.0,
        image_size: int | tuple[int, int] | None = None,
        horizon: int | None = None,
        min_horizon: int | None = None,
        action_dim: int = 14,
        name: str | None = None,
        api_key: str | None = None,
    ) -> None:
        for field, value in (("connect_timeout", connect_timeout), ("reply_timeout", reply_timeout)):
            if isinstance(value, bool) or not isinstance(value, int | float) or not value > 0:
                raise ValueError(f"{field}: expected a positive number of seconds, got {value!r}")
        if horizon is not None and (isinstance(horizon, bool) or not isinstance(horizon, int) or horizon < 1):
            raise ValueError(f"horizon: expected a positive int or None, got {horizon!r}")
        if min_horizon is not None and (
            isinstance(min_horizon, bool) or not isinstance(min_horizon, int) or min_horizon < 1
        ):
            raise ValueError(f"min_horizon: expected a positive int or None, got {min_horizon!r}")
        if isinstance(action_dim, bool) or not isinstance(action_dim, int) or action_dim < 1:
            raise ValueError(f"action_dim: expected a positive int, got {action_dim!r}")
        self.url = websocket_url(url, port)
        self.connect_timeout = float(connect_timeout)
        self.reply_timeout = float(reply_timeout)
        self.horizon = horizon
        self.min_horizon = min_horizon
        self.action_dim = action_dim
        self._name = name or f"openpi@{urlsplit(self.url).netloc}"
        self.timings: list[ChunkTiming] = []
        self._closed_because = ""
        self._ws: ClientConnection | None = None
        self._exit = contextlib.ExitStack()
        self.metadata: dict[str, Any] = self._connect(api_key)
        if image_size is not None:
            self.image_size = parse_image_size(image_size)
        elif "image_size" in self.metadata:
            try:
                self.image_size = parse_image_size(self.metadata["image_size"], "server metadata image_size")
            except ValueError as err:
                self.close()
                raise PolicyError(self._name, str(err)) from None
        else:
            self.image_size = DEFAULT_IMAGE_SIZE

    # ------------------------------------------------------------------ connection

    def _connect(self, api_key: str | None) -> dict[str, Any]:
        deadline = time.monotonic() + self.connect_timeout
        headers = {"Authorization": f"Api-Key {api_key}"} if api_key else None
        try:
            # compression=None and max_size=None as openpi: images are incompressible and large. Entered as
            # a context manager (websockets >= 17.1 deprecates direct use) and left in _drop.
            ws = self._exit.enter_context(
                connect(
                    self.url,
                    open_timeout=self.connect_timeout,
                    close_timeout=min(self.connect_timeout, 2.0),
                    compression=None,
                    max_size=None,
                    additional_headers=headers,
                )
            )
        except TimeoutError:
            raise PolicyTimeoutError(self._name, "connect", self.connect_timeout, self.url) from None
        except websockets.InvalidURI as err:
            raise ValueError(f"--checkpoints: {err}") from None
        except websockets.InvalidHandshake as err:  # something answered, but refused the websocket upgrade
            raise PolicyConnectionError(self._name, self.url, f"failed: {err}", kind="handshake failed") from None
        except OSError as err:  # nothing listening, no route, no such host
            raise PolicyConnectionError(self._name, self.url, f"failed: {err}", kind="unreachable") from None
        self._ws = ws
        try:
            first = ws.recv(timeout=max(0.0, deadline - time.monotonic()))
        except TimeoutError:
            self._drop("the metadata never came")
            raise PolicyTimeoutError(self._name, "connect", self.connect_timeout, self.url) from None
        except websockets.ConnectionClosed as err:
            self._drop("it closed during the handshake")
            raise PolicyConnectionError(
                self._name,
                self.url,
                f"closed before sending metadata ({_close_description(err)})",
                kind="handshake failed",
            ) from None
        if isinstance(first, str):
            raise self._server_error(first)
        try:
            metadata = unpackb(first)
        except ValueError as err:
            self._drop("its metadata was undecodable")
            raise PolicyError(
                self._name, f"undecodable metadata from {self.url}: {err}", kind="handshake failed"
            ) from None
        if not isinstance(metadata, dict):
            self._drop("its metadata was not a map")
            raise PolicyError(
                self._name,
                f"metadata from {self.url} is a {type(metadata).__name__}, expected a map",
                kind="handshake failed",
            )
        return metadata

    def _drop(self, because: str) -> None:
        """Close the connection for good: a late reply must never be taken for the next chunk's."""
        if self._ws is not None:
            self._ws = None
            self._closed_because = because
            self._exit.close()  # closes the websocket

    def _require_open(self) -> ClientConnection:
        if self._ws is None:
            raise PolicyConnectionError(self._name, self.url, f"is closed ({self._closed_because})")
        return self._ws

    def _server_error(self, text: str) -> PolicyServerError:
        """A text frame is openpi's error report; the close (code 1011) follows it."""
        code: int | None = None
        ws = self._ws
        if ws is not None:
            try:
                ws.recv(timeout=min(1.0, self.reply_timeout))
            except websockets.ConnectionClosed as err:
                frame = err.rcvd or err.sent
                code = None if frame is None else int(frame.code)
            except TimeoutError:
                pass
        self._drop("the server reported an error")
        return PolicyServerError(self._name, text, code)

    def _exchange(self, payload: bytes) -> Any:
        """Send one request and return the decoded reply; every failure is a typed PolicyError."""
        ws = self._require_open()
        try:
            ws.send(payload)
            reply = ws.recv(timeout=self.reply_timeout)
        except TimeoutError:
            self._drop(f"no reply within {self.reply_timeout:g} s")
            raise PolicyTimeoutError(self._name, "reply", self.reply_timeout, self.url) from None
        except websockets.ConnectionClosed as err:
            self._drop("the server closed it")
            raise PolicyConnectionError(self._name, self.url, f"closed ({_close_description(err)})") from None
        if isinstance(reply, str):
            raise self._server_error(reply)
        try:
            return unpackb(reply)
        except ValueError as err:
            raise PolicyError(self._name, f"undecodable reply: {err}") from None

    # ------------------------------------------------------------------ Policy protocol

    @property
    def name(self) -> str:
        return self._name

    def reset(self, seed: int | None = None) -> None:
        """Resets the served policy when the server supports it (ours); openpi servers have no reset."""
        if not (isinstance(self.metadata.get(PILWORLD_KEY), dict) and self.metadata[PILWORLD_KEY].get("reset")):
            return  # openpi's own client reset is a local no-op too
        reply = self._exchange(packb({RESET_KEY: True, "seed": seed}))
        if not (isinstance(reply, dict) and reply.get(RESET_KEY)):
            raise PolicyError(self._name, f"unexpected reply to a reset: {type(reply).__name__}")

    def infer(self, observation: Observation, instruction: str) -> NDArray[np.float32]:
        payload = packb(observation_to_openpi(observation, instruction, self.image_size))
        start = time.perf_counter()
        reply = self._exchange(payload)
        client_ms = (time.perf_counter() - start) * 1000.0
        if not isinstance(reply, dict) or "actions" not in reply:
            keys = sorted(map(str, reply)) if isinstance(reply, dict) else type(reply).__name__
            raise PolicyError(self._name, f"invalid reply: expected a map with 'actions', got {keys}")
        actions = validate_chunk(
            reply["actions"], self._name, dim=self.action_dim, horizon=self.horizon, min_horizon=self.min_horizon
        )
        timing = reply.get("server_timing")
        timing = timing if isinstance(timing, dict) else {}
        self.timings.append(
            ChunkTiming(client_ms, _number(timing.get("infer_ms")), _number(timing.get("prev_total_ms")))
        )
        return actions

    # ------------------------------------------------------------------ lifetime

    def healthz(self) -> bool:
        """``GET /healthz`` on the server's host and port (independent of the websocket)."""
        return healthz(self.url, timeout=self.connect_timeout)

    @property
    def connected(self) -> bool:
        return self._ws is not None

    def close(self) -> None:
        self._drop("closed by the client")

    def __enter__(self) -> OpenPiClient:
        return self

    def __exit__(
        self, exc_type: type[BaseException] | None, exc: BaseException | None, tb: TracebackType | None
    ) -> None:
        self.close()

    def __repr__(self) -> str:
        state = "connected" if self._ws is not None else f"closed: {self._closed_because}"
        return f"OpenPiClient({self.url!r}, image_size={self.image_size}, {state})"
