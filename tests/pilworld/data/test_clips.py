"""Clip indexing against the documented formula, the cached Dataset, and success/failure mixing."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import torch

from pilworld.data.clip_dataset import ClipDataset
from pilworld.data.clips import ClipSpec, index_clips, mix_weights
from pilworld.data.outcomes import Outcome, record_outcomes
from pilworld.data.spec import DatasetSpec
from pilworld.data.writer import EpisodeWriter

from .conftest import VIEWS, make_episode


def _formula_starts(T: int, K: int = 15, d: int = 3, W: int = 9) -> list[int]:
    """The documented formula, written out: t_c = c·W·Δ for c = 0 … ⌊(T − 1 − KΔ)/(WΔ)⌋."""
    if K * d > T - 1:
        return []
    return [c * W * d for c in range((T - 1 - K * d) // (W * d) + 1)]


@pytest.mark.parametrize("T", [1, 45, 46, 47, 72, 73, 74, 100, 118, 119, 300])
def test_clip_starts_match_formula_at_episode_ends(T: int) -> None:
    spec = ClipSpec()
    starts = spec.clip_starts(T).tolist()
    assert starts == _formula_starts(T)
    for t in starts:
        assert spec.future_indices(t)[-1] <= T - 1  # the last future frame exists
    if starts:  # and the next window would not fit
        assert starts[-1] + 27 + 45 > T - 1


def test_edge_lengths() -> None:
    spec = ClipSpec()
    assert spec.clip_starts(45).tolist() == []  # frames 0..44: x_45 is missing
    assert spec.clip_starts(46).tolist() == [0]  # frames 0..45: exactly one clip
    assert spec.clip_starts(73).tolist() == [0, 27]  # 27 + 45 = 72 = T − 1
    tail = ClipSpec(include_tail=True)
    assert tail.clip_starts(80).tolist() == [0, 27, 34]  # one more clip ending on frame 79
    assert tail.clip_starts(73).tolist() == [0, 27]  # already ends on the last frame


def test_history_future_and_action_indices() -> None:
    spec = ClipSpec()
    hist, valid = spec.history_indices(27)
    assert hist.tolist() == [12, 15, 18, 21, 24] and valid.all()
    hist, valid = spec.history_indices(6)
    assert hist.tolist() == [0, 0, 0, 0, 3] and valid.tolist() == [False, False, False, True, True]
    assert spec.future_indices(27).tolist() == list(range(30, 73, 3))
    assert spec.action_indices(27).tolist() == list(range(29, 72, 3))  # a_{t+kΔ} = a[t + kΔ − 1]
    refs = index_clips([46, 10, 73], spec)
    assert [(r.episode_index, r.t) for r in refs] == [(0, 0), (2, 0), (2, 27)]


def test_mix_weights() -> None:
    success = np.array([1, 1, 1, 0, -1], dtype=np.int8)
    w = mix_weights(success, 0.5)
    assert w[:3].sum() == pytest.approx(0.4) and w[3] == pytest.approx(0.4) and w[4] == pytest.approx(0.2)
    np.testing.assert_allclose(mix_weights(success, None), 0.2)
    with pytest.raises(ValueError, match="no clips from failed episodes"):
        mix_weights(np.array([1, 1], dtype=np.int8), 0.5)
    with pytest.raises(ValueError, match="success_fraction"):
        mix_weights(success, 1.5)


@pytest.fixture
def dataset(tmp_path: Path) -> Path:
    root = tmp_path / "ds"
    spec = DatasetSpec(video_mode="lossless", views={v: (32, 48) for v in VIEWS})
    with EpisodeWriter(root, spec) as w:
        for k, T in enumerate((100, 46, 30)):
            w.append(make_episode(T, k))
    record_outcomes(
        root,
        [
            Outcome(0, "sim_state", "sim_state", True, 100),
            Outcome(1, "sim_state", "sim_state", False, 46),
        ],
    )
    return root


def test_clip_dataset_items_match_source_frames(dataset: Path, tmp_path: Path) -> None:
    ds = ClipDataset(dataset, cache_dir=tmp_path / "cache")
    # Episode 0 (T = 100): starts 0, 27, 54; episode 1 (T = 46): 0; episode 2 (T = 30): none.
    assert [(c.episode_index, c.t) for c in ds.clips] == [(0, 0), (0, 27), (0, 54), (1, 0)]
    item = ds[2]
    ep = make_episode(100, 0)
    assert item["history"].shape == (3, 5, 3, 32, 48) and item["history"].dtype == torch.uint8
    assert item["future"].shape == (3, 15, 3, 32, 48) and item["current"].shape == (3, 3, 32, 48)
    for vi, v in enumerate(VIEWS):
        hwc = ep.images[v]
        np.testing.assert_array_equal(item["current"][vi].permute(1, 2, 0).numpy(), hwc[54])
        np.testing.assert_array_equal(item["future"][vi, -1].permute(1, 2, 0).numpy(), hwc[99])
        np.testing.assert_array_equal(item["history"][vi, 0].permute(1, 2, 0).numpy(), hwc[39])
    np.testing.assert_array_equal(item["actions"].numpy(), ep.action[56:99:3])
    np.testing.assert_array_equal(item["state"].numpy(), ep.state[54])
    assert item["instruction"] == ep.task and item["success"] == 1 and item["frame_index"] == 54
    assert ds[3]["success"] == 0 and ds[0]["history_valid"].sum() == 0
    # Decoded once: one cache file per (episode with clips, view), holding only the frames clips use.
    files = sorted((tmp_path / "cache").rglob("*.npy"))
    assert len(files) == 6
    assert np.load(files[0]).shape[0] == len(ds.needed_frames(0)) < 100


def test_sampler_mixes_success_and_failure(dataset: Path, tmp_path: Path) -> None:
    ds = ClipDataset(dataset, cache_dir=tmp_path / "cache")
    drawn = list(ds.sampler(4000, success_fraction=0.5, seed=1))
    failure_share = np.mean([ds.clips[i].episode_index == 1 for i in drawn])
    assert 0.45 < failure_share < 0.55  # 1 failed clip of 4, drawn half the time
    with pytest.raises(ValueError, match="views"):
        ClipDataset(dataset, views=["cam_top"])


def test_clip_spec_for_a_dataset_recorded_at_the_stride() -> None:
    from pilworld.data.clips import ClipSpec

    assert ClipSpec.for_dataset(1).stride == 3  # frames at the control rate: Δ = 3 frames
    assert ClipSpec.for_dataset(3).stride == 1  # frames at the stride: Δ = 1 stored frame
    assert ClipSpec.for_dataset(3, future=10).future == 10
    with pytest.raises(ValueError, match="does not divide"):
        ClipSpec.for_dataset(2)
