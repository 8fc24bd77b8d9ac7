"""The chunk-level environment contract both branches implement (DESIGN.md, "Data flow").

``reset(start)`` puts the branch at the shared start and returns the observation the policy sees
first; ``step(chunk)`` consumes one policy chunk ``float32[H_π, 14]`` and returns a
:class:`~pilworld.types.Segment` of K observations at stride Δ, the last of which is fed back to the
policy. The closed loop (:func:`pilworld.rollout.closed_loop`) drives either branch without knowing
which one it has, so a policy cannot tell the robot from the world model.
"""

from __future__ import annotations

from typing import Protocol, runtime_checkable

import numpy as np
from numpy.typing import NDArray

from pilworld.types import ActionChunk, ChunkSpec, Observation, Segment, Start


class EnvError(RuntimeError):
    """A branch cannot run (not reset, robot moved away from the start, model/rig mismatch)."""


@runtime_checkable
class Env(Protocol):
    """One branch: ``origin`` is ``"real"`` or ``"imagined"`` (the value stored with its episodes)."""

    @property
    def origin(self) -> str: ...

    @property
    def spec(self) -> ChunkSpec: ...

    def reset(self, start: Start) -> Observation: ...

    def step(self, chunk: ActionChunk | NDArray[np.floating]) -> Segment: ...


def as_chunk(chunk: ActionChunk | NDArray[np.floating], spec: ChunkSpec, dof: int) -> ActionChunk:
    """Validate a policy chunk for one round: numeric, finite, ``dof`` wide and at least K·Δ long."""
    c = chunk if isinstance(chunk, ActionChunk) else ActionChunk.from_array(chunk, name="chunk")
    if c.dim != dof:
        raise ValueError(f"chunk: expected {dof} action dimensions, got shape {c.actions.shape}")
    if c.horizon < spec.executed_steps:
        raise ValueError(
            f"chunk: has {c.horizon} steps but K·Δ = {spec.frames}·{spec.stride} = {spec.executed_steps} are executed"
        )
    return c
