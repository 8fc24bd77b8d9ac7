"""Synthetic episodes for the store tests: 3 views, 14-d, deterministic content per frame."""

from __future__ import annotations

import numpy as np
import pytest

from pilworld.data.episode import Episode

VIEWS = ("cam_high", "cam_left_wrist", "cam_right_wrist")


def make_episode(length: int, k: int, size: tuple[int, int] = (32, 48), origin: str = "real") -> Episode:
    """Frames whose pixels encode (view, frame, episode), smooth enough for lossy codecs."""
    h, w = size
    yy, xx = np.mgrid[0:h, 0:w]
    images = {}
    for i, view in enumerate(VIEWS):
        t = np.arange(length)[:, None, None]
        r = 20 + xx[None] * 2 + t * 2 + i * 10  # ≤ 20 + 94 + 2·(T−1) + 20: no wrap-around edges
        g = 30 + yy[None] * 3 + t
        b = np.broadcast_to((k * 37 + i * 11) % 200, r.shape)
        images[view] = np.stack([r, g, b], axis=-1).astype(np.uint8)
    rng = np.random.default_rng(k)
    return Episode(
        images=images,
        state=rng.standard_normal((length, 14)).astype(np.float32),
        action=rng.standard_normal((length, 14)).astype(np.float32),
        task=("sort the cubes by size.", "pick up the bowls and stack them one by one.")[k % 2],
        origin=origin,
        subtask_index=k % 3,
        checkpoint=f"ckpt-{k % 2}",
        seed=100 + k,
        round_index=(np.arange(length) // 45).astype(np.int64),
    )


@pytest.fixture
def episodes() -> list[Episode]:
    return [make_episode(20 + 7 * k, k, origin=("real", "imagined")[k % 2]) for k in range(3)]
