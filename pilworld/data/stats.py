"""Feature statistics in LeRobot's format: per-episode, and aggregated into ``meta/stats.json``.

LeRobot normalises policy inputs with these: every numeric feature gets ``min``, ``max``, ``mean``,
``std`` (per dimension) and ``count``; images get per-channel values in [0, 1] with shape (3, 1, 1)
computed on a subsample of frames (as LeRobot does, to keep writing cheap).
"""

from __future__ import annotations

from typing import Any

import numpy as np
from numpy.typing import NDArray

STAT_KEYS = ("min", "max", "mean", "std", "count")
_IMAGE_SAMPLES = 100  # frames per episode used for image statistics


def vector_stats(values: NDArray[Any]) -> dict[str, NDArray[np.float64]]:
    """(T, D) or (T,) → per-dimension stats; scalars become shape (1,)."""
    x = np.asarray(values, dtype=np.float64).reshape(len(values), -1)
    return {
        "min": x.min(axis=0),
        "max": x.max(axis=0),
        "mean": x.mean(axis=0),
        "std": x.std(axis=0),
        "count": np.array([x.shape[0]], dtype=np.float64),
    }


def image_stats(frames: NDArray[np.uint8]) -> dict[str, NDArray[np.float64]]:
    """(T, H, W, 3) uint8 → per-channel stats in [0, 1], shaped (3, 1, 1) like LeRobot's.

    Computed from one 256-bin histogram per channel, which holds everything min, max, mean and std
    need for 8-bit pixels: ~9× cheaper than converting the frames to float64 (this ran for every view of
    every recorded episode and was a third of a benchmark worker's time), and exact up to rounding.
    """
    if frames.dtype != np.uint8 or frames.ndim != 4 or frames.shape[-1] != 3 or frames.shape[0] == 0:
        raise ValueError(
            f"image_stats: expected (T, H, W, 3) uint8 frames with T ≥ 1, got {frames.dtype} {frames.shape}"
        )
    T = frames.shape[0]
    idx = np.unique(np.linspace(0, T - 1, min(T, _IMAGE_SAMPLES)).round().astype(int))
    pixels = frames[idx].reshape(-1, 3).astype(np.intp) + np.arange(3) * 256  # channel c → bins 256c … 256c+255
    hist = np.bincount(pixels.ravel(), minlength=3 * 256).reshape(3, 256).astype(np.float64)
    level = np.arange(256) / 255.0
    n = hist.sum(axis=1)
    mean = hist @ level / n
    var = (hist * (level[None, :] - mean[:, None]) ** 2).sum(axis=1) / n
    present = hist > 0
    out = {
        "min": level[present.argmax(axis=1)],
        "max": level[255 - present[:, ::-1].argmax(axis=1)],
        "mean": mean,
        "std": np.sqrt(var),
    }
    stats = {k: v.reshape(3, 1, 1) for k, v in out.items()}
    stats["count"] = np.array([len(idx)], dtype=np.float64)
    return stats


def aggregate(per_episode: list[dict[str, NDArray[np.float64]]]) -> dict[str, NDArray[np.float64]]:
    """Combine per-episode stats (count-weighted mean, pooled variance, global min/max)."""
    if not per_episode:
        raise ValueError("aggregate: no statistics to combine")
    counts = np.array([s["count"][0] for s in per_episode])
    w = (counts / counts.sum()).reshape(-1, *([1] * per_episode[0]["mean"].ndim))
    means = np.stack([s["mean"] for s in per_episode])
    mean = (w * means).sum(axis=0)
    var = (w * (np.stack([s["std"] for s in per_episode]) ** 2 + (means - mean) ** 2)).sum(axis=0)
    return {
        "min": np.min(np.stack([s["min"] for s in per_episode]), axis=0),
        "max": np.max(np.stack([s["max"] for s in per_episode]), axis=0),
        "mean": mean,
        "std": np.sqrt(var),
        "count": np.array([counts.sum()], dtype=np.float64),
    }


def to_jsonable(stats: dict[str, dict[str, NDArray[np.float64]]]) -> dict[str, dict[str, Any]]:
    return {feat: {k: v.tolist() for k, v in s.items()} for feat, s in stats.items()}
