"""The ``Policy`` contract and the adapter for plain Python callables.

A policy maps one observation and an instruction to an action chunk ``float32[H_π, 14]`` of absolute
commands. The closed loop (``pilworld.rollout``) never looks inside: a scripted checkpoint, a Python
function and a remote openpi server are interchangeable, and a policy cannot tell the robot from the
world model because both hand it the same :class:`~pilworld.types.Observation`.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any, Protocol, runtime_checkable

import numpy as np
from numpy.typing import NDArray

from pilworld.types import ActionChunk, Observation


class PolicyError(RuntimeError):
    """A policy failed to produce a chunk (remote error, timeout, invalid reply); ``policy`` names it.

    ``kind`` says what happened in a few words (one of :data:`FAILURE_KINDS`); the CLI prints the error
    as one line, so the message is one line too. A runner that knows more (which checkpoint, which
    branch) adds it with :meth:`in_context` rather than wrapping the error, so the type survives.
    """

    kind = "invalid reply"

    def __init__(self, policy: str, message: str, *, kind: str | None = None) -> None:
        self.policy = policy
        self.message = " ".join(message.split())  # one line, whatever the remote end sent
        if kind is not None:
            self.kind = kind
        self.checkpoint = ""
        self.where = ""
        self.hint = ""
        super().__init__(str(self))

    def in_context(self, checkpoint: str, where: str = "", hint: str = "") -> PolicyError:
        """Name the checkpoint (as the user spelled it), where it failed and what to do; returns ``self``."""
        self.checkpoint = checkpoint
        self.where = where
        self.hint = hint
        self.args = (str(self),)
        return self

    def __str__(self) -> str:
        subject = f"checkpoint {self.checkpoint}" if self.checkpoint else f"policy {self.policy}"
        if self.where:
            subject += f" ({self.where})"
        return f"{subject}: {self.kind}: {self.message}" + (f"; {self.hint}" if self.hint else "")

    def __reduce__(self) -> tuple[Any, ...]:
        # Crosses process boundaries (imagine's worker processes) with every attribute, whatever the subclass.
        return (_rebuild_error, (type(self), dict(self.__dict__)))


def _rebuild_error(cls: type[PolicyError], state: dict[str, Any]) -> PolicyError:
    err = cls.__new__(cls)
    err.__dict__.update(state)
    err.args = (str(err),)
    return err


# What a policy failure can be, as PolicyError.kind says it (docs/policies.md lists them).
FAILURE_KINDS = (
    "unreachable",  # nothing listening, DNS failure, connection refused
    "handshake failed",  # refused the websocket upgrade, closed or garbled before sending metadata
    "timeout",  # no connection, metadata or reply within the configured seconds
    "server error",  # the server raised and sent its traceback (openpi's error report)
    "connection closed",  # the server dropped a connection that was working
    "invalid actions",  # wrong shape, too few steps, non-numbers, NaN or inf
    "invalid reply",  # undecodable frame, or a reply that is not {"actions": ...}
    "invalid metadata",  # handshake metadata the run cannot honour (a malformed reset_pose)
)


@runtime_checkable
class Policy(Protocol):
    """Anything with a name, a per-episode ``reset`` and ``infer(observation, instruction)``."""

    @property
    def name(self) -> str: ...

    def reset(self, seed: int | None = None) -> None:
        """Forget per-episode memory; ``seed`` makes a stochastic policy repeatable."""
        ...

    def infer(self, observation: Observation, instruction: str) -> NDArray[np.float32]:
        """The action chunk for this observation, ``float32[H_π, D]``."""
        ...


PolicyFn = Callable[[Observation, str], NDArray[np.floating]]


class CallablePolicy:
    """Wraps ``fn(observation, instruction) -> (H, D) array`` as a :class:`Policy` (validated replies)."""

    def __init__(self, fn: PolicyFn, name: str = "callable") -> None:
        if not callable(fn):
            raise ValueError(f"fn: expected a callable (observation, instruction) -> actions, got {type(fn).__name__}")
        self._fn = fn
        self._name = name

    @property
    def name(self) -> str:
        return self._name

    def reset(self, seed: int | None = None) -> None:
        """A plain function keeps no per-episode memory."""

    def infer(self, observation: Observation, instruction: str) -> NDArray[np.float32]:
        return validate_chunk(self._fn(observation, instruction), self._name)


def validate_chunk(
    actions: object,
    policy: str,
    *,
    dim: int | None = 14,
    horizon: int | None = None,
    min_horizon: int | None = None,
) -> NDArray[np.float32]:
    """Cast a reply to ``float32[H, D]``; a wrong shape, too few steps (``min_horizon``), a non-number or a
    NaN/inf raises :class:`PolicyError` of kind "invalid actions"."""

    def bad(message: str) -> PolicyError:
        return PolicyError(policy, f"invalid action chunk: {message}", kind="invalid actions")

    try:
        chunk = ActionChunk.from_array(actions, name="actions")
    except ValueError as err:
        raise bad(str(err)) from None
    if dim is not None and chunk.dim != dim:
        raise bad(f"expected {dim} values per step, got shape {chunk.actions.shape}")
    if horizon is not None and chunk.horizon != horizon:
        raise bad(f"expected {horizon} steps, got shape {chunk.actions.shape}")
    if min_horizon is not None and chunk.horizon < min_horizon:
        raise bad(f"expected at least {min_horizon} steps (K·Δ), got shape {chunk.actions.shape}")
    return np.array(chunk.actions, dtype=np.float32)
