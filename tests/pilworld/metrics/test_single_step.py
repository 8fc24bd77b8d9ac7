"""Single-step scores of round 0: hand-computed PSNR, per-frame lists of length K, mismatched chunks skipped."""

from __future__ import annotations

import math

import pytest

from pilworld.data.pairs import load_pairs
from pilworld.data.reader import EpisodeStore
from pilworld.metrics.single_step import single_step_metrics
from pilworld.world_model.metrics import PSNR_CAP_DB
from tests.pilworld.metrics.synthetic import VIEWS, K, SynthPair, write_paired


@pytest.fixture(scope="module")
def store(tmp_path_factory: pytest.TempPathFactory) -> EpisodeStore:
    root = tmp_path_factory.mktemp("single_step") / "run"
    pairs = [
        SynthPair(subtask=0, offset=0),  # the world model got round 0 exactly right
        SynthPair(subtask=1, offset=10),  # every pixel 10 levels off: MSE 100 (no clipping: pixels are 40..199)
        SynthPair(subtask=2, offset=0, action_shift={1: 0.2}),  # the robot was sent another command in round 0
        SynthPair(subtask=3, offset=0, action_shift={K: 0.2}),  # row K is round 1's: does not matter
        SynthPair(subtask=4, branches=("imagined",)),  # incomplete pair
    ]
    return EpisodeStore(write_paired(root, pairs, unpaired=1))


def test_pairs_are_grouped_and_incomplete_ones_counted(store: EpisodeStore) -> None:
    paired = load_pairs(store.root, store)
    assert [p.pair_id.rsplit("/", 1)[1] for p in paired.pairs] == [f"subtask{i}" for i in range(4)]
    assert [(p.imagined, p.real) for p in paired.pairs] == [(0, 1), (2, 3), (4, 5), (6, 7)]
    assert paired.incomplete == ["sort_cubes/ckpt_a/seed0/subtask4"] and paired.unpaired_episodes == 1
    assert paired.pairs[0].setting == ("sort_cubes", "ckpt_a")


def test_round_zero_scores_by_hand(store: EpisodeStore) -> None:
    out = single_step_metrics(store, load_pairs(store.root, store).pairs, lpips=False)
    assert (out["K"], out["pairs"], out["pairs_used"], out["pairs_skipped"]) == (K, 4, 3, 1)
    skipped = out["skipped"][0]
    assert skipped["pair"].endswith("subtask2") and skipped["first_differing_row"] == 1
    assert skipped["max_abs_action_diff"] == pytest.approx(0.2, abs=1e-6)
    assert out["starts_identical"] == 3
    # Used: two exact pairs (100 dB cap, MSE 0) and one with MSE 100 on every image.
    psnr_100 = 10 * math.log10(255**2 / 100)
    assert out["psnr"] == pytest.approx((2 * PSNR_CAP_DB + psnr_100) / 3)
    assert out["psnr_pooled"] == pytest.approx(10 * math.log10(255**2 / (100 / 3)))  # PSNR of the mean MSE
    assert out["exact"] == pytest.approx(2 / 3)
    assert out["lpips"] is None and out["lpips_reason"] == "disabled by the caller"
    for name in ("psnr", "psnr_pooled", "ssim", "exact"):
        assert len(out["per_frame"][name]) == K
    assert out["per_frame"]["psnr_pooled"] == pytest.approx([out["psnr_pooled"]] * K)
    assert set(out["per_view"]) == set(VIEWS)
    assert out["per_view"]["cam_high"]["ssim"] < 1.0
    # The frozen baseline copies the start frame; the synthetic frames are independent noise, so it is far worse.
    assert out["frozen"]["psnr_pooled"] < out["psnr_pooled"] and out["gain_over_frozen_pooled_db"] > 5
    assert set(out["tasks"]) == {"sort_cubes"} and out["tasks"]["sort_cubes"]["clips"] == 3


def test_a_loose_tolerance_admits_the_filtered_pair_and_none_usable_is_reported(store: EpisodeStore) -> None:
    pairs = load_pairs(store.root, store).pairs
    assert single_step_metrics(store, pairs, action_atol=1.0, lpips=False)["pairs_used"] == 4
    out = single_step_metrics(store, pairs[2:3], lpips=False)
    assert out["pairs_used"] == 0 and "no usable pair" in out["reason"] and "psnr" not in out
