"""One imagined branch: a policy in closed loop against the world model from a stored start.

The same function runs the imagined branch of a paired run and of an imagined-only run, so that the
same start, checkpoint, seed and model give the same episode in both, bit for bit.
"""

from __future__ import annotations

import contextlib
import hashlib
import os
from collections.abc import Iterator
from typing import Any

from hw_drivers.errors import SafetyViolationError
from pilworld.control_video.gamma import ControlVideo
from pilworld.data.episode import Episode
from pilworld.envs import ImaginedEnv, SafetyFilter
from pilworld.paired.episodes import rollout_episode
from pilworld.policies.base import Policy
from pilworld.rollout import Rollout, closed_loop
from pilworld.types import ChunkSpec, RobotSpec, Start
from pilworld.world_model.base import WorldModel

THREADS_ENV = "PILWORLD_TORCH_THREADS"
MAX_DEFAULT_THREADS = 8


def inference_threads() -> int:
    """Torch's intra-op thread count for every imagined branch: ``$PILWORLD_TORCH_THREADS``, else the CPUs (≤ 8).

    Fixed rather than whatever the process has: torch's CPU kernels split their reductions by thread,
    and one thread instead of two changed up to 3 pixels per 128² view of a v2 rollout. A paired run,
    an imagined-only run's worker processes and its Ray workers therefore all run the same count, and
    the same start gives the same branch, bit for bit, on one machine.
    """
    raw = os.environ.get(THREADS_ENV, "").strip()
    if raw:
        if not raw.isdigit() or int(raw) < 1:
            raise ValueError(f"{THREADS_ENV}: expected a positive integer, got {raw!r}")
        return int(raw)
    return max(1, min(os.cpu_count() or 1, MAX_DEFAULT_THREADS))


@contextlib.contextmanager
def torch_threads(count: int) -> Iterator[None]:
    """Run with torch's intra-op thread count set to ``count``, restored afterwards."""
    import torch

    before = torch.get_num_threads()
    torch.set_num_threads(count)
    try:
        yield
    finally:
        torch.set_num_threads(before)


def run_imagined(
    model: WorldModel,
    gamma: ControlVideo,
    spec: ChunkSpec,
    robot: RobotSpec,
    policy: Policy,
    start: Start,
    *,
    seed: int,
    steps: int | None,
    control_rate_hz: float,
) -> Rollout:
    """The imagined rollout of ``policy`` from ``start`` (policy and world model seeded with ``seed``)."""
    policy.reset(seed=seed)
    env = ImaginedEnv(
        model,
        gamma,
        spec,
        control_rate_hz=control_rate_hz,
        seed=seed,
        steps=steps,
        safety=SafetyFilter(robot),  # the robot's filter: the same commands in both branches
    )
    # A refused chunk ends an imagined rollout early (kept, and judged as it is); the first chunk is
    # computed from the real start, so a refusal there still raises.
    with torch_threads(inference_threads()):
        return closed_loop(
            policy, env, start.subtask.instruction, spec.rounds, start=start, stop_on=(SafetyViolationError,)
        )


def branch_episode(rollout: Rollout, *, checkpoint: str, seed: int, extra: dict[str, Any]) -> Episode:
    """A branch's rollout as a stored episode, with the first chunk's digest and why it stopped early."""
    # The first policy chunk's digest: equal in both branches (same start, policy and seed), which is
    # the premise of comparing their first rounds frame by frame (pilworld.metrics.single_step).
    ep_extra = {**extra, "chunk0": hashlib.sha256(rollout.chunks[0].tobytes()).hexdigest()[:16]}
    if rollout.stopped:
        ep_extra["stopped"] = rollout.stopped
    return rollout_episode(rollout, checkpoint=checkpoint, seed=seed, extra=ep_extra)
