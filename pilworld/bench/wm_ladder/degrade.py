"""Rung 2's degradations: what a world model's frames carry without being wrong (autoencoder, blur, artefacts)."""

from __future__ import annotations

import dataclasses

import numpy as np

from pilworld.bench.wm_ladder.model import FrameAutoencoder
from pilworld.bench.wm_ladder.settings import DEGRADATIONS, Frames
from pilworld.data.episode import Episode

BLUR_SIGMA_AT_128 = 1.0  # px, scaled with the image width
JPEG_QUALITY = 80
NOISE_LEVELS = 2.0  # per-pixel Gaussian noise, uint8 levels
COLOUR_SHIFT_LEVELS = 2.0  # per-frame per-channel offset, uint8 levels


def blur_frames(frames: Frames, sigma_px: float) -> Frames:
    """Gaussian blur of σ px on every frame [N, H, W, 3]."""
    import cv2

    return np.stack([cv2.GaussianBlur(f, (0, 0), sigmaX=sigma_px, borderType=cv2.BORDER_REFLECT) for f in frames])


def artefact_frames(frames: Frames, rng: np.random.Generator) -> Frames:
    """JPEG at :data:`JPEG_QUALITY`, then per-pixel noise and a per-frame per-channel colour shift."""
    import cv2

    out = []
    for f in frames:
        ok, buf = cv2.imencode(".jpg", cv2.cvtColor(f, cv2.COLOR_RGB2BGR), [cv2.IMWRITE_JPEG_QUALITY, JPEG_QUALITY])
        if not ok:
            raise RuntimeError("JPEG encoding failed")
        decoded = cv2.imdecode(buf, cv2.IMREAD_COLOR)
        if decoded is None:
            raise RuntimeError("JPEG decoding failed")
        g = cv2.cvtColor(decoded, cv2.COLOR_BGR2RGB).astype(np.float64)
        g += rng.normal(0.0, NOISE_LEVELS, g.shape) + rng.normal(0.0, COLOUR_SHIFT_LEVELS, 3)
        out.append(np.clip(np.round(g), 0, 255).astype(np.uint8))
    return np.stack(out)


def degrade_episode(
    ep: Episode, kind: str, *, autoencode: FrameAutoencoder | None = None, rng: np.random.Generator | None = None
) -> Episode:
    """``ep`` with every view's frames degraded (``plain``: unchanged); states and actions untouched."""
    if kind == "plain":
        return ep
    images: dict[str, Frames] = {}
    for v, frames in ep.images.items():
        f = np.asarray(frames, dtype=np.uint8)
        if kind == "autoencoded":
            if autoencode is None:
                raise ValueError("degrade_episode: 'autoencoded' needs an autoencoder")
            images[v] = autoencode(f)
        elif kind == "blur":
            images[v] = blur_frames(f, BLUR_SIGMA_AT_128 * f.shape[2] / 128.0)
        elif kind == "artefact":
            images[v] = artefact_frames(f, rng if rng is not None else np.random.default_rng(0))
        else:
            raise ValueError(f"degradation: expected one of {list(DEGRADATIONS)}, got {kind!r}")
    return dataclasses.replace(ep, images=images)
