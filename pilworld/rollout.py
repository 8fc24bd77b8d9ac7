"""The one closed-loop function both branches run (paper §3.1): query, execute K·Δ steps, observe, repeat.

``closed_loop`` does not know which branch it drives; the paired runner calls it once with a
:class:`~pilworld.envs.RobotEnv` and once with an :class:`~pilworld.envs.ImaginedEnv` from the same
start. Only the first K·Δ steps of each H_π-step chunk are executed (the rest are dropped) and the
terminal observation of the round is the next query's input.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray

from pilworld.envs.base import Env
from pilworld.policies.base import Policy, validate_chunk
from pilworld.types import Observation, Segment, Start


@dataclass
class RoundTiming:
    """Wall-clock seconds of one round: the policy query and the branch's step."""

    policy_s: float
    env_s: float


@dataclass
class Rollout:
    """One branch of one subtask: the start, then one segment per round, with the chunks queried."""

    origin: str
    start: Start
    instruction: str
    segments: list[Segment] = field(default_factory=list)
    chunks: list[NDArray[np.float32]] = field(default_factory=list)
    timings: list[RoundTiming] = field(default_factory=list)
    stopped: str = ""  # why the rollout ended before its last round ("" = it ran every round)

    @property
    def observations(self) -> list[Observation]:
        """The start observation, then every recorded frame (stride Δ), in order."""
        return [self.start.observation, *(o for s in self.segments for o in s.observations)]

    @property
    def seconds(self) -> float:
        return sum(t.policy_s + t.env_s for t in self.timings)


def closed_loop(
    policy: Policy,
    env: Env,
    instruction: str,
    rounds: int,
    *,
    start: Start,
    stop_on: tuple[type[Exception], ...] = (),
) -> Rollout:
    """Run ``rounds`` closed-loop rounds of ``policy`` in ``env`` from ``start``.

    An exception of a ``stop_on`` type raised by ``env.step`` after the first round ends the rollout
    there (``Rollout.stopped`` says why) instead of propagating: the imagined branch uses it for a chunk
    the safety filter refuses, which a policy can only produce from imagined frames (the first chunk
    is the same in both branches, so a refusal there still raises).
    """
    if isinstance(rounds, bool) or not isinstance(rounds, int) or rounds < 1:
        raise ValueError(f"rounds: expected an integer >= 1, got {rounds!r}")
    if not isinstance(instruction, str) or not instruction.strip():
        raise ValueError(f"instruction: expected a non-empty string, got {instruction!r}")
    obs = env.reset(start)
    rollout = Rollout(origin=env.origin, start=start, instruction=instruction)
    dof = int(obs.state.shape[0])
    for _ in range(rounds):
        t0 = time.perf_counter()
        chunk = validate_chunk(policy.infer(obs, instruction), policy.name, dim=dof)
        t1 = time.perf_counter()
        try:
            segment = env.step(chunk)
        except stop_on as exc:
            if not rollout.segments:
                raise
            rollout.stopped = f"{type(exc).__name__}: {exc}"
            break
        t2 = time.perf_counter()
        rollout.chunks.append(chunk)
        rollout.segments.append(segment)
        rollout.timings.append(RoundTiming(policy_s=t1 - t0, env_s=t2 - t1))
        obs = segment.last
    return rollout
