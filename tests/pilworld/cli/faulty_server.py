"""A small openpi websocket server that misbehaves on request, for the CLI's policy fault matrix.

Written on the ``websockets`` library our own :class:`~pilworld.policies.openpi.server.PolicyServer` uses,
but independently of it: it answers with a real scripted checkpoint until ``fail_after`` inference
requests have been answered, then does what ``mode`` says. It stays on one port across modes (and
across :meth:`stop` / :meth:`start`), because a run folder names its checkpoint by the server's URL and a
resumed run must name the same one. Every wait is bounded; :meth:`stop` releases a stalled handler.
"""

from __future__ import annotations

import contextlib
import socket
import threading
import traceback
from collections.abc import Mapping
from typing import Any

import numpy as np
import websockets
from websockets.frames import CloseCode
from websockets.sync.server import Server, ServerConnection, serve

from pilworld.config.rig import RigConfig
from pilworld.policies.openpi.wire import PILWORLD_KEY, RESET_KEY, openpi_to_observation, packb, unpackb
from pilworld.policies.scripted import ScriptedPolicy

MODES = ("good", "close_before_metadata", "exception", "stall", "wrong_shape", "nan")
STALL_BOUND_S = 20.0  # a stalled handler gives up by itself even if nobody releases it


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


class FaultyServer:
    """Serve ``checkpoint`` of the rig at ``rig_path`` on ``ws://127.0.0.1:port``, misbehaving per ``mode``."""

    def __init__(
        self, rig_path: str, checkpoint: str, port: int, *, extra_metadata: Mapping[str, Any] | None = None
    ) -> None:
        rig = RigConfig.load(rig_path)
        self.policy = ScriptedPolicy(rig, checkpoint)
        self.size = (rig.image_size.height, rig.image_size.width)
        self.port = port
        self.mode = "good"
        self.fail_after = 0  # inference requests answered well before misbehaving
        self.answered = 0
        self.extra_metadata = dict(extra_metadata or {})
        self._release = threading.Event()
        self._lock = threading.Lock()
        self._server: Server | None = None
        self._thread: threading.Thread | None = None

    @property
    def url(self) -> str:
        return f"ws://127.0.0.1:{self.port}"

    def set_mode(self, mode: str, fail_after: int = 0) -> None:
        if mode not in MODES:
            raise ValueError(f"mode: expected one of {MODES}, got {mode!r}")
        self._release.set()  # let a stalled handler go
        self._release = threading.Event()
        self.mode, self.fail_after, self.answered = mode, fail_after, 0

    def start(self) -> FaultyServer:
        server = serve(self._handle, "127.0.0.1", self.port, compression=None, max_size=None)
        self._server = server
        self._thread = threading.Thread(target=server.serve_forever, name=f"faulty-server:{self.port}", daemon=True)
        self._thread.start()
        return self

    def stop(self) -> None:
        self._release.set()
        server, self._server = self._server, None
        if server is not None:
            server.shutdown()
        if self._thread is not None:
            self._thread.join(5.0)
            self._thread = None

    def __enter__(self) -> FaultyServer:
        return self.start()

    def __exit__(self, *exc: object) -> None:
        self.stop()

    # ------------------------------------------------------------------ protocol

    def _handle(self, ws: ServerConnection) -> None:
        # The client went away (it gives up after a fault) or idled past the bound: nothing to report.
        with contextlib.suppress(websockets.ConnectionClosed, TimeoutError):
            self._serve(ws)

    def _serve(self, ws: ServerConnection) -> None:
        if self.mode == "close_before_metadata":
            ws.close(CloseCode.GOING_AWAY, "not ready")
            return
        metadata = {"image_size": list(self.size), PILWORLD_KEY: {"policy": self.policy.name, "reset": True}}
        ws.send(packb({**metadata, **self.extra_metadata}))
        while True:
            frame = ws.recv(timeout=STALL_BOUND_S)
            message = unpackb(frame if isinstance(frame, bytes) else frame.encode())
            if isinstance(message, dict) and message.get(RESET_KEY):
                with self._lock:
                    self.policy.reset(message.get("seed"))
                ws.send(packb({RESET_KEY: True}))
                continue
            observation, instruction = openpi_to_observation(message, self.size)
            with self._lock:
                actions = np.asarray(self.policy.infer(observation, instruction))
                misbehave = self.mode != "good" and self.answered >= self.fail_after
                self.answered += 1
            if not misbehave:
                ws.send(packb({"actions": actions, "server_timing": {"infer_ms": 1.0}}))
            elif self.mode == "exception":
                try:
                    raise RuntimeError("model exploded: CUDA out of memory")
                except RuntimeError:
                    ws.send(traceback.format_exc())
                ws.close(CloseCode.INTERNAL_ERROR, "Internal server error. Traceback included in previous frame.")
                return
            elif self.mode == "stall":
                self._release.wait(STALL_BOUND_S)
                return
            elif self.mode == "wrong_shape":
                ws.send(packb({"actions": actions[:, :7]}))
            elif self.mode == "nan":
                bad = actions.copy()
                bad[3, 2] = np.nan
                ws.send(packb({"actions": bad}))
