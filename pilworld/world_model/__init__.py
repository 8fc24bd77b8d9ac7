"""The chunk-wise world model (paper §3.2): one interface (:mod:`.base`) and one loader keyed by a folder's format
(:mod:`.loader`, folders in :mod:`.folder`) over three sibling formats: the composite, v2 (:mod:`.composite`), the
paper-style latent video model, v1 (:mod:`.latent`), and the Wan2.1 backend (:mod:`.wan`). Training loops and
their checkpoints are in :mod:`.training`; clip batching and image resizing shared by all in :mod:`.batching`
and :mod:`.resized`; single-step image metrics in :mod:`.metrics`.

``DEFAULT_CHECKPOINT`` is the shipped model, world model v2 (:mod:`.composite`: geometry, tracked objects and a
0.09 M-parameter compositing network) trained on the simulated rig; ``V1_CHECKPOINT`` the paper-style latent
model it replaced (see docs/world_model.md).
"""

from __future__ import annotations

from pathlib import Path

DEFAULT_CHECKPOINT = Path(__file__).resolve().parent / "weights" / "sim_composite"
# v1, the paper-style latent model (marker Γ, 8× VAE, 1-step flow, task adapters): its presets, sampling steps
# and ablations are what `bench speed-accuracy`, `bench world-model` and the ladder's autoencoder rung measure.
# Not installed with the package (19 MB for a model no command uses by default): it lives in a checkout's
# weights/v1/, beside the benchmarks' other weights.
V1_CHECKPOINT = Path(__file__).resolve().parents[2] / "weights" / "v1" / "sim_small"
