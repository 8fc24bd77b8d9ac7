"""openpi-compatible policy adapters: a websocket client (:class:`OpenPiClient`) and a loopback server
(:class:`PolicyServer`) wrapping any local policy, both speaking openpi's msgpack wire format."""

from pilworld.policies.openpi.client import ChunkTiming, OpenPiClient, healthz, websocket_url
from pilworld.policies.openpi.errors import PolicyConnectionError, PolicyServerError, PolicyTimeoutError
from pilworld.policies.openpi.server import PolicyServer

__all__ = [
    "ChunkTiming",
    "OpenPiClient",
    "PolicyConnectionError",
    "PolicyServer",
    "PolicyServerError",
    "PolicyTimeoutError",
    "healthz",
    "websocket_url",
]
