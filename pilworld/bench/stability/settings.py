"""The bench's seeds, models and sizes, shared by the horizon runs and the probes (see the package docstring)."""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

STABILITY_SEED0 = 7_000_000
PROBE_SEED0 = STABILITY_SEED0 + 500
DONOR_SEED_OFFSET = 250  # the action shuffle's donor: the same subtask on layout seed + this
DEFAULT_MODELS = ("pilworld", "v2_paper_gamma")
HORIZONS = (1, 2, 5, 10, 20)
SHUFFLE_ROUNDS = 2
HEAD = "cam_high"
QUICK_CHECKPOINTS = ("scripted_step_01k", "scripted_step_30k")

Chunk = NDArray[np.float32]
Frames = dict[str, NDArray[np.uint8]]  # view → (T, H, W, 3)
