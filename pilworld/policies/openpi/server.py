"""``PolicyServer``: serves any local :class:`~pilworld.policies.base.Policy` in openpi's websocket format.

The behaviour of openpi's ``src/openpi/serving/websocket_policy_server.py`` (our own implementation):
metadata first, then request → ``policy.infer`` → ``{"actions", "server_timing": {"infer_ms",
"prev_total_ms"}}``; an exception sends ``traceback.format_exc()`` as a text frame and closes with
code 1011; ``GET /healthz`` answers 200 "OK". So an openpi client (or our
:class:`~pilworld.policies.openpi.client.OpenPiClient`) can drive our scripted checkpoints, and tests get a
loopback fake of a real VLA server.

Additions, advertised in the metadata so a client only uses them when present: ``image_size``
[height, width] (what the policy expects; other sizes are resized with padding on arrival) and
``pilworld: {policy, reset: True}`` — a reset request ``{"pilworld_reset": True, "seed": …}`` answered
by ``{"pilworld_reset": True}`` (openpi's protocol has no reset; its client resets locally only).

Connections are served from threads (websockets' synchronous server); inference is serialised with a
lock because policies keep per-episode state.
"""

from __future__ import annotations

import http
import logging
import threading
import time
import traceback
from collections.abc import Mapping
from types import TracebackType
from typing import Any

import numpy as np
import websockets
from websockets.frames import CloseCode
from websockets.http11 import Request, Response
from websockets.sync.server import Server, ServerConnection, serve

from pilworld.config.network import is_loopback
from pilworld.policies.base import Policy
from pilworld.policies.openpi.wire import (
    PILWORLD_KEY,
    RESET_KEY,
    openpi_to_observation,
    packb,
    parse_image_size,
    unpackb,
)

logger = logging.getLogger(__name__)

ERROR_CLOSE_REASON = "Internal server error. Traceback included in previous frame."  # openpi's wording


def _health_check(connection: ServerConnection, request: Request) -> Response | None:
    if request.path == "/healthz":
        return connection.respond(http.HTTPStatus.OK, "OK\n")
    return None  # go on with the websocket handshake


class PolicyServer:
    """Serve ``policy`` on ``ws://host:port`` (``port=0``: any free port; :meth:`start` returns it).

    Bound to loopback unless ``allow_remote=True``: the protocol has no authentication, so anyone who
    can reach the port can drive the policy. ``image_size`` (int or (height, width)) is announced in
    the metadata and enforced on arrival.
    """

    def __init__(
        self,
        policy: Policy,
        host: str = "127.0.0.1",
        port: int = 0,
        *,
        metadata: Mapping[str, Any] | None = None,
        image_size: int | tuple[int, int] | None = None,
        allow_remote: bool = False,
    ) -> None:
        if not isinstance(policy, Policy):
            raise TypeError(f"policy: expected a Policy (name, reset, infer), got {type(policy).__name__}")
        if not allow_remote and not is_loopback(host):
            raise ValueError(
                f"host: {host!r} is not a loopback address; the openpi protocol has no authentication, so "
                "serving there lets anyone on the network drive the policy — pass allow_remote=True "
                "(pilworld policy serve --allow-remote) if that is intended"
            )
        if isinstance(port, bool) or not isinstance(port, int) or not 0 <= port < 65536:
            raise ValueError(f"port: expected 0 (any free port) or 1..65535, got {port!r}")
        self.policy = policy
        self.host = host
        self.image_size = None if image_size is None else parse_image_size(image_size)
        self.metadata: dict[str, Any] = dict(metadata or {})
        if self.image_size is not None:
            self.metadata["image_size"] = list(self.image_size)
        self.metadata[PILWORLD_KEY] = {"policy": policy.name, "reset": True}
        try:
            self._metadata_frame = packb(self.metadata)
        except (TypeError, ValueError) as err:
            raise ValueError(f"metadata: cannot be sent in the openpi wire format: {err}") from None
        self._requested_port = port
        self._server: Server | None = None
        self._thread: threading.Thread | None = None
        self._infer_lock = threading.Lock()
        self.port: int | None = None

    # ------------------------------------------------------------------ lifetime

    def start(self) -> int:
        """Bind, serve from a background thread and return the port."""
        if self._server is not None:
            raise RuntimeError("PolicyServer.start: already serving")
        server = serve(
            self._handle,
            self.host,
            self._requested_port,
            compression=None,
            max_size=None,
            process_request=_health_check,
            logger=logger,
        )
        self._server = server
        self.port = int(server.socket.getsockname()[1])
        self._thread = threading.Thread(target=server.serve_forever, name=f"policy-server:{self.port}", daemon=True)
        self._thread.start()
        return self.port

    @property
    def url(self) -> str:
        if self.port is None:
            raise RuntimeError("PolicyServer.url: not started")
        host = f"[{self.host}]" if ":" in self.host else self.host
        return f"ws://{host}:{self.port}"

    def stop(self, timeout: float = 5.0) -> None:
        """Close the socket and every connection; waits up to ``timeout`` s for handlers in ``infer``."""
        server, self._server = self._server, None
        if server is None:
            return
        # shutdown() waits for handler threads, and one may be stuck in a slow policy: bound the wait.
        stopper = threading.Thread(target=server.shutdown, name="policy-server-stop", daemon=True)
        stopper.start()
        stopper.join(timeout)
        if stopper.is_alive():
            logger.warning("policy server on port %s: a handler was still busy after %.1f s", self.port, timeout)
        if self._thread is not None:
            self._thread.join(timeout)
            self._thread = None

    def __enter__(self) -> PolicyServer:
        if self._server is None:
            self.start()
        return self

    def __exit__(
        self, exc_type: type[BaseException] | None, exc: BaseException | None, tb: TracebackType | None
    ) -> None:
        self.stop()

    # ------------------------------------------------------------------ protocol

    def _reply(self, message: Any, prev_total_ms: float | None) -> dict[str, Any]:
        if isinstance(message, dict) and message.get(RESET_KEY):
            seed = message.get("seed")
            if seed is not None and (isinstance(seed, bool) or not isinstance(seed, int)):
                raise ValueError(f"reset: seed must be an int or None, got {seed!r}")
            with self._infer_lock:
                self.policy.reset(seed)
            return {RESET_KEY: True}
        observation, instruction = openpi_to_observation(message, self.image_size)
        with self._infer_lock:
            start = time.perf_counter()
            actions = self.policy.infer(observation, instruction)
            infer_ms = (time.perf_counter() - start) * 1000.0
        timing: dict[str, float] = {"infer_ms": infer_ms}
        if prev_total_ms is not None:  # the previous cycle, since a cycle's total includes its own send
            timing["prev_total_ms"] = prev_total_ms
        return {"actions": np.asarray(actions), "server_timing": timing}

    def _handle(self, ws: ServerConnection) -> None:
        ws.send(self._metadata_frame)
        prev_total_ms: float | None = None
        while True:
            try:
                raw = ws.recv()
            except websockets.ConnectionClosed:
                return
            start = time.perf_counter()
            try:
                if isinstance(raw, str):
                    raise ValueError("request: expected a binary msgpack frame, got a text frame")
                ws.send(packb(self._reply(unpackb(raw), prev_total_ms)))
            except websockets.ConnectionClosed:
                return
            except Exception as err:
                logger.warning("policy %s failed on a request: %s: %s", self.policy.name, type(err).__name__, err)
                try:
                    ws.send(traceback.format_exc())
                    ws.close(CloseCode.INTERNAL_ERROR, ERROR_CLOSE_REASON)
                except websockets.ConnectionClosed:
                    pass
                return
            prev_total_ms = (time.perf_counter() - start) * 1000.0
