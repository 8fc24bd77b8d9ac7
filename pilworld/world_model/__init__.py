"""The chunk-wise world model (paper §3.2): one interface (:mod:`.base`), the native PiL-World model
(:mod:`.model`, presets in :mod:`.config`), training (:mod:`.training`) and the Wan2.1 backend (:mod:`.wan`).

``DEFAULT_CHECKPOINT`` is the shipped ``small`` model trained on the simulated rig (see docs/world_model.md).
"""

from __future__ import annotations

from pathlib import Path

DEFAULT_CHECKPOINT = Path(__file__).resolve().parent / "weights" / "sim_small"
# v1, the paper-style latent model (marker Γ, 8× VAE, 1-step flow), named for comparisons (bench chunk-latency).
V1_CHECKPOINT = Path(__file__).resolve().parent / "weights" / "sim_small"
