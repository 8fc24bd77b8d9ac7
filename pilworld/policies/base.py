"""The ``Policy`` contract and the adapter for plain Python callables.

A policy maps one observation and an instruction to an action chunk ``float32[H_π, 14]`` of absolute
commands. The closed loop (``pilworld.rollout``) never looks inside: a scripted checkpoint, a Python
function and a remote openpi server are interchangeable, and a policy cannot tell the robot from the
world model because both hand it the same :class:`~pilworld.types.Observation`.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Protocol, runtime_checkable

import numpy as np
from numpy.typing import NDArray

from pilworld.types import ActionChunk, Observation


class PolicyError(RuntimeError):
    """A policy failed to produce a chunk (remote error, timeout, invalid reply); ``policy`` names it."""

    def __init__(self, policy: str, message: str) -> None:
        super().__init__(f"policy {policy}: {message}")
        self.policy = policy


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
    actions: object, policy: str, *, dim: int | None = 14, horizon: int | None = None
) -> NDArray[np.float32]:
    """Cast a reply to ``float32[H, D]``; a wrong shape, a non-number or a NaN raises :class:`PolicyError`."""
    try:
        chunk = ActionChunk.from_array(actions, name="actions")
    except ValueError as err:
        raise PolicyError(policy, f"invalid action chunk: {err}") from None
    if dim is not None and chunk.dim != dim:
        raise PolicyError(
            policy, f"invalid action chunk: expected {dim} values per step, got shape {chunk.actions.shape}"
        )
    if horizon is not None and chunk.horizon != horizon:
        raise PolicyError(policy, f"invalid action chunk: expected {horizon} steps, got shape {chunk.actions.shape}")
    return np.array(chunk.actions, dtype=np.float32)
