"""Typed failures of a remote policy; all are :class:`~pilworld.policies.base.PolicyError`.

An invalid reply (wrong shape, NaN, a non-numeric dtype, an undecodable frame) is a plain
``PolicyError`` (kind "invalid actions" or "invalid reply") with a message saying what was wrong.
"""

from __future__ import annotations

from pilworld.policies.base import PolicyError


class PolicyServerError(PolicyError):
    """The server raised while inferring; ``remote_traceback`` is the text frame it sent (openpi sends
    ``traceback.format_exc()`` and then closes with code 1011, kept in ``close_code``)."""

    kind = "server error"

    def __init__(self, policy: str, remote_traceback: str, close_code: int | None = None) -> None:
        last = next((line for line in reversed(remote_traceback.strip().splitlines()) if line.strip()), "")
        super().__init__(policy, f"the server failed: {last or 'no message'}")
        self.remote_traceback = remote_traceback
        self.close_code = close_code


class PolicyTimeoutError(PolicyError):
    """No connection (``stage="connect"``) or no reply (``stage="reply"``) within ``seconds``."""

    kind = "timeout"

    def __init__(self, policy: str, stage: str, seconds: float, url: str) -> None:
        what = "connecting to" if stage == "connect" else "waiting for a reply from"
        super().__init__(policy, f"timed out after {seconds:g} s {what} {url}")
        self.stage = stage
        self.seconds = seconds
        self.url = url


class PolicyConnectionError(PolicyError):
    """The server refused the connection, or the connection closed; never retried silently.

    ``kind``: "unreachable" (nothing answered), "handshake failed" (it answered but never completed the
    openpi handshake: upgrade refused, closed or garbled before the metadata) or "connection closed".
    """

    kind = "connection closed"

    def __init__(self, policy: str, url: str, reason: str, *, kind: str | None = None) -> None:
        super().__init__(policy, f"connection to {url} {reason}", kind=kind)
        self.url = url
        self.reason = reason
