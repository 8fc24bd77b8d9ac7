"""A family of scripted "checkpoints" of graded quality, the stand-in for VLA checkpoints.

One skill value in [0, 1] scales every way a policy can be wrong, the way an under-trained VLA is:

* a grasp offset and a placement offset (systematic for one object in one episode, so re-planning
  does not average them away), drawn with standard deviation ``(1 − skill) · σ``;
* a release height above the target (dropping instead of setting down);
* slower, more hesitant motion (a timeout within the R rounds of a subtask is a failure too).

The errors are drawn from a generator seeded by (episode seed, object), so a checkpoint is
deterministic given its seed: both branches of a paired run see the same policy.
"""

from __future__ import annotations

import zlib
from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class Checkpoint:
    """A named skill level."""

    name: str
    skill: float  # 1 = the best scripted behaviour, 0 = the worst


# Ordered worst → best; names read like the training steps of a VLA fine-tune.
CHECKPOINTS: tuple[Checkpoint, ...] = (
    Checkpoint("scripted_step_01k", 0.15),
    Checkpoint("scripted_step_02k", 0.45),
    Checkpoint("scripted_step_05k", 0.65),
    Checkpoint("scripted_step_10k", 0.82),
    Checkpoint("scripted_step_30k", 1.0),
)
BEST_CHECKPOINT = CHECKPOINTS[-1].name


def checkpoint(name: str) -> Checkpoint:
    """The checkpoint called ``name``; ``ValueError`` lists the valid names."""
    for c in CHECKPOINTS:
        if c.name == name:
            return c
    raise ValueError(
        f"checkpoint: unknown scripted checkpoint {name!r}; choose one of {', '.join(c.name for c in CHECKPOINTS)}"
    )


@dataclass(frozen=True)
class Errors:
    """The mistakes a checkpoint makes on one object in one episode."""

    grasp_offset: tuple[float, float]  # [m], added to the perceived grasp point
    place_offset: tuple[float, float]  # [m], added to the goal
    release_extra: float  # [m], extra release height
    speed: float  # fraction of the nominal Cartesian speed


GRASP_SIGMA = 0.02
PLACE_SIGMA = 0.035
DROP_MAX = 0.06


def errors_for(skill: float, seed: int, obj: str) -> Errors:
    if not 0.0 <= skill <= 1.0:
        raise ValueError(f"skill: expected a value in [0, 1], got {skill!r}")
    rng = np.random.default_rng([seed & 0xFFFFFFFF, zlib.crc32(obj.encode())])
    bad = 1.0 - skill
    g = rng.normal(0.0, GRASP_SIGMA * bad, 2)
    p = rng.normal(0.0, PLACE_SIGMA * bad, 2)
    drop = float(rng.uniform(0.0, DROP_MAX * bad))
    return Errors(
        grasp_offset=(float(g[0]), float(g[1])),
        place_offset=(float(p[0]), float(p[1])),
        release_extra=drop,
        speed=1.0 - 0.45 * bad,
    )
