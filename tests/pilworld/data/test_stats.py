"""Image statistics from per-channel histograms match the float64 definition LeRobot uses."""

from __future__ import annotations

import numpy as np
import pytest

from pilworld.data.stats import _IMAGE_SAMPLES, image_stats


def _reference(frames: np.ndarray) -> dict[str, np.ndarray]:
    T = frames.shape[0]
    idx = np.unique(np.linspace(0, T - 1, min(T, _IMAGE_SAMPLES)).round().astype(int))
    x = frames[idx].astype(np.float64).reshape(-1, 3) / 255.0
    return {"min": x.min(0), "max": x.max(0), "mean": x.mean(0), "std": x.std(0)}


@pytest.mark.parametrize("shape", [(1, 4, 4, 3), (7, 16, 12, 3), (250, 8, 8, 3)])
def test_image_stats_equal_the_float_definition(shape: tuple[int, ...]) -> None:
    rng = np.random.default_rng(sum(shape))
    frames = rng.integers(0, 256, shape, dtype=np.uint8)
    frames[..., 1] //= 3  # channels with different ranges
    frames[..., 2] = 200  # and a constant one (std 0, min = max)
    got = image_stats(frames)
    for key, want in _reference(frames).items():
        assert got[key].shape == (3, 1, 1)
        np.testing.assert_allclose(got[key].ravel(), want, rtol=0, atol=1e-12, err_msg=key)
    assert got["count"].tolist() == [min(shape[0], _IMAGE_SAMPLES)]
    assert abs(got["std"][2, 0, 0]) < 1e-12 and got["min"][2, 0, 0] == got["max"][2, 0, 0] == 200 / 255


def test_image_stats_extremes() -> None:
    frames = np.zeros((2, 3, 3, 3), dtype=np.uint8)
    frames[1, 0, 0] = 255
    got = image_stats(frames)
    assert got["min"].ravel().tolist() == [0.0] * 3 and got["max"].ravel().tolist() == [1.0] * 3


@pytest.mark.parametrize(
    "frames",
    [np.zeros((2, 4, 4, 3), np.float32), np.zeros((4, 4, 3), np.uint8), np.zeros((0, 4, 4, 3), np.uint8)],
)
def test_image_stats_rejects_what_is_not_rgb_frames(frames: np.ndarray) -> None:
    with pytest.raises(ValueError, match="image_stats"):
        image_stats(frames)
