"""``OpenPiClient`` against the loopback ``PolicyServer``: handshake, images, errors, timeouts, validation.

Every network wait is bounded (small timeouts, stalls released in ``finally``).
"""

from __future__ import annotations

import socket
import threading
import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from numpy.typing import NDArray
from websockets.sync.server import ServerConnection, serve

from pilworld.config.rig import RigConfig
from pilworld.policies.base import CallablePolicy, Policy, PolicyError
from pilworld.policies.openpi import (
    OpenPiClient,
    PolicyConnectionError,
    PolicyServer,
    PolicyServerError,
    PolicyTimeoutError,
    healthz,
)
from pilworld.policies.openpi.wire import packb
from pilworld.types import HEAD_VIEW, Observation

pytestmark = pytest.mark.timeout(30)
ROOT = Path(__file__).resolve().parents[4]
SIM = ROOT / "configs" / "rig" / "sim_dual_ur5e.yaml"


def _obs(height: int = 96, width: int = 128, seed: int = 0) -> Observation:
    rng = np.random.default_rng(seed)
    images = {v: rng.integers(1, 256, (height, width, 3), dtype=np.uint8) for v in ("cam_high", "cam_left_wrist")}
    return Observation(images=images, state=rng.normal(size=14).astype(np.float32), timestamp=0.0)


class RawPolicy:
    """Returns whatever ``fn`` gives, unvalidated (a misbehaving remote model); records what it saw."""

    def __init__(self, fn: Callable[[Observation, str], Any]) -> None:
        self.fn = fn
        self.seen: list[tuple[Observation, str]] = []
        self.resets: list[int | None] = []

    @property
    def name(self) -> str:
        return "raw"

    def reset(self, seed: int | None = None) -> None:
        self.resets.append(seed)

    def infer(self, observation: Observation, instruction: str) -> NDArray[np.float32]:
        self.seen.append((observation, instruction))
        return self.fn(observation, instruction)  # type: ignore[no-any-return]


def _echo_state(obs: Observation, _: str) -> NDArray[np.float64]:
    return np.tile(obs.state.astype(np.float64), (50, 1))


@contextmanager
def served(policy: Policy, **kwargs: Any) -> Iterator[PolicyServer]:
    server = PolicyServer(policy, **kwargs)
    server.start()
    try:
        yield server
    finally:
        server.stop(timeout=3.0)


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


# ---------------------------------------------------------------------- handshake and round trip


def test_handshake_returns_metadata_and_server_size_is_used() -> None:
    policy = RawPolicy(_echo_state)
    with served(policy, metadata={"reset_pose": [0, -1.5, 1.5], "note": "hi"}, image_size=(64, 80)) as server:
        with OpenPiClient(server.url, connect_timeout=2, reply_timeout=2) as client:
            assert client.metadata["reset_pose"] == [0, -1.5, 1.5] and client.metadata["note"] == "hi"
            assert client.metadata["image_size"] == [64, 80]
            assert client.metadata["pilworld"] == {"policy": "raw", "reset": True}
            assert client.image_size == (64, 80)
            obs = _obs(96, 128)
            chunk = client.infer(obs, "stack the bowls")
        seen, prompt = policy.seen[0]
    assert prompt == "stack the bowls"
    # The server saw every view at its size: 96×128 scaled by 80/128 to 60×80, padded 2 rows top/bottom.
    for view in obs.views:
        image = seen.images[view]
        assert image.shape == (64, 80, 3)
        assert not image[:2].any() and not image[62:].any() and image[2:62].all(axis=-1).mean() > 0.99
    np.testing.assert_array_equal(seen.state, obs.state)
    # A float64 reply is cast to float32.
    assert chunk.dtype == np.float32 and chunk.shape == (50, 14)
    np.testing.assert_array_equal(chunk, np.tile(obs.state, (50, 1)))


def test_image_size_defaults_to_224_and_can_be_overridden() -> None:
    policy = RawPolicy(_echo_state)
    with served(policy) as server:  # no image_size in the metadata, as from a real openpi server
        with OpenPiClient(server.url, connect_timeout=2, reply_timeout=2) as client:
            assert client.image_size == (224, 224) and "image_size" not in client.metadata
            client.infer(_obs(), "x")
        with OpenPiClient("127.0.0.1", server.port, image_size=32, connect_timeout=2, reply_timeout=2) as client:
            client.infer(_obs(), "x")
    assert [o.images[HEAD_VIEW].shape for o, _ in policy.seen] == [(224, 224, 3), (32, 32, 3)]


def test_timings_health_and_reset_are_forwarded() -> None:
    policy = RawPolicy(_echo_state)
    with served(policy, image_size=32) as server:
        assert healthz(server.url)
        with OpenPiClient(server.url, connect_timeout=2, reply_timeout=2) as client:
            assert client.healthz()
            for _ in range(3):
                client.infer(_obs(), "x")
            client.reset(seed=5)
            client.reset()
            timings = client.timings
    assert policy.resets == [5, None]
    assert len(timings) == 3
    for t in timings:
        assert t.client_ms > 0 and t.server_infer_ms is not None and 0 <= t.server_infer_ms <= t.client_ms
    assert timings[0].server_prev_total_ms is None and timings[2].server_prev_total_ms is not None


def test_scripted_policy_through_the_server_equals_calling_it_directly(robots: Callable[[str], Any]) -> None:
    from pilworld.policies.scripted import BEST_CHECKPOINT, ScriptedPolicy

    robot = robots("sort_cubes")
    obs = robot.reset(seed=3, subtask=0, history=0).observation
    instruction = robot.task.instruction
    rig = RigConfig.load(SIM)
    direct = ScriptedPolicy(rig, BEST_CHECKPOINT, seed=0)
    direct.reset(seed=11)
    expected = [direct.infer(obs, instruction) for _ in range(2)]
    size = (rig.image_size.height, rig.image_size.width)
    with (
        served(ScriptedPolicy(rig, BEST_CHECKPOINT, seed=0), image_size=size) as server,
        OpenPiClient(server.url, connect_timeout=2, reply_timeout=10, horizon=50) as client,
    ):
        client.reset(seed=11)
        got = [client.infer(obs, instruction) for _ in range(2)]
    for a, b in zip(expected, got, strict=True):
        np.testing.assert_array_equal(a, b)


# ---------------------------------------------------------------------- failures


def test_server_exception_becomes_a_typed_error_with_the_remote_traceback() -> None:
    def boom(obs: Observation, instruction: str) -> NDArray[np.float32]:
        raise RuntimeError(f"model exploded on {instruction!r}")

    with served(CallablePolicy(boom, name="boom"), image_size=32) as server:
        client = OpenPiClient(server.url, connect_timeout=2, reply_timeout=2)
        with pytest.raises(PolicyServerError, match="model exploded on 'fold'") as info:
            client.infer(_obs(), "fold")
        assert "Traceback (most recent call last)" in info.value.remote_traceback
        assert "RuntimeError: model exploded on 'fold'" in info.value.remote_traceback
        assert info.value.close_code == 1011
        assert isinstance(info.value, PolicyError)
        # No silent reconnect: the connection is gone and says why.
        with pytest.raises(PolicyConnectionError, match=r"closed .*the server reported an error"):
            client.infer(_obs(), "fold")
        assert not client.connected


def test_stalled_server_hits_the_reply_timeout() -> None:
    release = threading.Event()

    def stall(obs: Observation, instruction: str) -> NDArray[np.float32]:
        release.wait(5.0)
        return np.zeros((50, 14), np.float32)

    with served(CallablePolicy(stall), image_size=32) as server:
        try:
            client = OpenPiClient(server.url, connect_timeout=2, reply_timeout=0.3)
            start = time.monotonic()
            with pytest.raises(PolicyTimeoutError, match=r"timed out after 0.3 s waiting for a reply") as info:
                client.infer(_obs(), "x")
            assert 0.25 < time.monotonic() - start < 1.5
            assert info.value.stage == "reply" and info.value.seconds == 0.3 and info.value.url == server.url
            # A late reply must not be taken for the next chunk's: the connection is closed.
            with pytest.raises(PolicyConnectionError, match=r"no reply within 0\.3 s"):
                client.infer(_obs(), "x")
        finally:
            release.set()


def test_connect_failures_are_typed_and_quick() -> None:
    port = _free_port()  # nothing listens there any more
    start = time.monotonic()
    with pytest.raises((PolicyConnectionError, PolicyTimeoutError), match=f"127.0.0.1:{port}"):
        OpenPiClient("127.0.0.1", port, connect_timeout=1.0)
    assert time.monotonic() - start < 1.5
    assert not healthz(f"ws://127.0.0.1:{port}", timeout=0.5)
    # A port that accepts TCP but never answers the websocket handshake: a connect timeout.
    with socket.socket() as silent:
        silent.bind(("127.0.0.1", 0))
        silent.listen(1)
        url = f"ws://127.0.0.1:{silent.getsockname()[1]}"
        start = time.monotonic()
        with pytest.raises(PolicyTimeoutError, match=r"timed out after 0\.3 s connecting to") as info:
            OpenPiClient(url, connect_timeout=0.3)
        assert info.value.stage == "connect" and time.monotonic() - start < 1.5


@pytest.mark.parametrize(
    ("reply", "message"),
    [
        (np.zeros((50, 7)), "expected 14 values per step, got shape (50, 7)"),
        (np.zeros(14), "expected shape (N×N), got (14,)"),
        (np.full((50, 14), np.nan), "values must be finite, got nan at index (0, 0)"),
        (np.array([["a"] * 14] * 50), "expected real numbers, got dtype <U1"),
        (np.zeros((10, 14)), "expected 50 steps, got shape (10, 14)"),
    ],
)
def test_invalid_replies_are_rejected_with_a_clear_error(reply: NDArray[Any], message: str) -> None:
    with (
        served(RawPolicy(lambda obs, instruction: reply), image_size=32) as server,
        OpenPiClient(server.url, connect_timeout=2, reply_timeout=2, horizon=50) as client,
    ):
        with pytest.raises(PolicyError, match="invalid action chunk") as info:
            client.infer(_obs(), "x")
        assert message in str(info.value)
        assert client.timings == []


def test_reply_without_actions_and_dropped_connections() -> None:
    """A bare websockets server (not ours) sending odd replies, then hanging up without a word."""

    def handler(ws: ServerConnection) -> None:
        ws.send(packb({}))
        ws.recv()
        ws.send(packb({"action": [1, 2]}))  # a typo'd key
        ws.recv()
        ws.close()

    with serve(handler, "127.0.0.1", 0) as server:
        thread = threading.Thread(target=server.serve_forever, daemon=True)
        thread.start()
        try:
            url = f"ws://127.0.0.1:{server.socket.getsockname()[1]}"
            with OpenPiClient(url, connect_timeout=2, reply_timeout=2) as client:
                assert client.metadata == {} and client.image_size == (224, 224)
                with pytest.raises(PolicyError, match=r"expected a map with 'actions', got \['action'\]"):
                    client.infer(_obs(), "x")
                with pytest.raises(PolicyConnectionError, match=f"connection to {url} closed"):
                    client.infer(_obs(), "x")
        finally:
            server.shutdown()
            thread.join(3)


def test_server_refuses_non_loopback_hosts_and_bad_policies() -> None:
    policy = RawPolicy(_echo_state)
    with pytest.raises(ValueError, match=r"not a loopback address.*allow_remote=True"):
        PolicyServer(policy, host="0.0.0.0")
    assert PolicyServer(policy, host="0.0.0.0", allow_remote=True).host == "0.0.0.0"  # not started
    assert PolicyServer(policy, host="localhost").host == "localhost"
    with pytest.raises(TypeError, match="expected a Policy"):
        PolicyServer(lambda obs, instruction: None)  # type: ignore[arg-type]
    with pytest.raises(ValueError, match="metadata: cannot be sent"):
        PolicyServer(policy, metadata={"bad": object()})


def test_client_argument_checks() -> None:
    with pytest.raises(ValueError, match="reply_timeout"):
        OpenPiClient("127.0.0.1", 1, reply_timeout=0)
    with pytest.raises(ValueError, match="expected a ws:// or wss:// URL"):
        OpenPiClient("http://127.0.0.1:8000")
    with pytest.raises(ValueError, match="already names a port"):
        OpenPiClient("ws://127.0.0.1:8000", 8001)
