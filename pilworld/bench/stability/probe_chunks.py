"""The chunks the probes execute and imagine: counterfactuals (3), out-of-distribution motions (6), transplants (7)."""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from pilworld.bench.stability.settings import Chunk
from pilworld.types import LEFT_ARM, LEFT_GRIP, RIGHT_ARM, RIGHT_GRIP, ChunkSpec

GRIPS = (LEFT_GRIP, RIGHT_GRIP)
JITTER_RAD = 0.05
# At most the joints' speed cap per control step (π rad/s at 30 Hz ≈ 0.105 rad): the filter slows a faster
# target to that cap, the gap to the next target then grows, and past 0.35 rad the filter refuses.
FAST_STEP_RAD = 0.1
EXECUTED_STEPS = ChunkSpec().executed_steps  # K·Δ = 45 of the policy's H_π = 50 rows are executed


def _arms_only(chunk: NDArray[np.floating], base: Chunk) -> Chunk:
    """``chunk`` with the grippers' columns back to the policy's (the probes change arm motion only)."""
    out = np.asarray(chunk, dtype=np.float32).copy()
    out[:, GRIPS] = base[:, GRIPS]
    return out


def hold_chunk(base: Chunk, state: Chunk) -> Chunk:
    return _arms_only(np.repeat(state[None], base.shape[0], axis=0), base)


def reverse_chunk(base: Chunk, state: Chunk) -> Chunk:
    return _arms_only(2.0 * state[None] - base, base)


def fast_chunk(base: Chunk, state: Chunk) -> Chunk:
    """The displacement ×3, each step's increment limited to FAST_STEP_RAD (the filter refuses jumps > 0.35)."""
    want = state[None] + 3.0 * (base - state[None])
    out = np.empty_like(want)
    prev = state.astype(np.float64)
    for i, row in enumerate(want):
        prev = prev + np.clip(row - prev, -FAST_STEP_RAD, FAST_STEP_RAD)
        out[i] = prev
    return _arms_only(out, base)


def jitter_chunk(base: Chunk, state: Chunk, rng: np.random.Generator) -> Chunk:
    # Clipped so consecutive targets stay inside the safety filter's per-step cap (0.35 rad).
    noise = np.clip(rng.normal(0.0, JITTER_RAD, size=base.shape), -2 * JITTER_RAD, 2 * JITTER_RAD).astype(np.float32)
    noise[:, GRIPS] = 0.0  # the grippers keep the policy's command
    return (base + noise).astype(np.float32)


def offset_chunk(base: Chunk, state: Chunk) -> Chunk:
    """+0.3 rad on both shoulder lifts, ramped in over the chunk (a jump would be refused by the safety filter)."""
    out = base.copy()
    # Full 0.3 rad by the last executed step (K·Δ of the H_π rows run), then held.
    ramp = 0.3 * np.minimum(np.arange(1, base.shape[0] + 1, dtype=np.float32) / EXECUTED_STEPS, 1.0)
    out[:, LEFT_ARM.start + 1] += ramp
    out[:, RIGHT_ARM.start + 1] += ramp
    return out


def transplant(donor: NDArray[np.floating], donor_state: NDArray[np.floating], state: NDArray[np.floating]) -> Chunk:
    """Another episode's chunk on this branch: the arms move from ``state`` by the donor chunk's displacement
    from ``donor_state`` (the donor's state when its policy computed the chunk); the grippers get the donor's
    commands."""
    d = np.asarray(donor, dtype=np.float64)
    s0 = np.asarray(donor_state, dtype=np.float64)
    s = np.asarray(state, dtype=np.float64)
    if d.ndim != 2 or s0.shape != (d.shape[1],) or s.shape != (d.shape[1],):
        raise ValueError(
            f"transplant: expected a chunk (H, D) and two states (D,), got {d.shape}, {s0.shape}, {s.shape}"
        )
    out = s[None] + (d - s0[None])
    out[:, GRIPS] = d[:, GRIPS]
    return out.astype(np.float32)
