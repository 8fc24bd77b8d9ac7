"""End to end: a tiny paired run on the simulated rig, a fake judge on both branches, then metrics.json."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from pilworld.config.rig import RigConfig
from pilworld.data.episode import Episode
from pilworld.data.outcomes import JudgeKind
from pilworld.judges.base import JudgeContext, Verdict, judge_dataset
from pilworld.metrics import compute_run_metrics, write_metrics
from pilworld.paired import PairedConfig, paired_run
from pilworld.types import ChunkSpec

SIM = "configs/rig/sim_dual_ur5e.yaml"
SPEC = ChunkSpec(rounds=1)
CHECKPOINTS = ["scripted_step_30k", "scripted_step_01k"]


class FakeVision:
    """Success = the strong checkpoint; sees a hallucination at frame 5 of the weak one's imagined rollout."""

    judge_id = "fake_vision"
    kind: JudgeKind = "vision"

    def judge(self, episode: Episode, context: JudgeContext) -> Verdict:
        strong = episode.checkpoint == CHECKPOINTS[0]
        hallucination = 5 if episode.origin == "imagined" and not strong else None
        return Verdict(success=strong, first_hallucination_frame=hallucination)


@pytest.fixture(scope="module")
def run(tmp_path_factory: pytest.TempPathFactory) -> Path:
    out = tmp_path_factory.mktemp("metrics_e2e") / "paired"
    cfg = PairedConfig(rig=SIM, task="sort_cubes", checkpoints=CHECKPOINTS, subtasks=1, out=str(out), spec=SPEC)
    paired_run(cfg, progress=False)
    judge_dataset(out, [FakeVision()], RigConfig.load(SIM))
    return out


def test_metrics_json_of_a_paired_run(run: Path) -> None:
    m = write_metrics(run)
    assert json.loads((run / "metrics.json").read_text()) == m
    task = m["tasks"]["sort_cubes"]
    assert {"sr_real", "sr_imag", "abs_delta_sr", "hfr", "sr_real_checker", "n_subtasks", "ci95"} <= set(task)
    assert {"abs_delta_sr", "hfr", "pearson", "mmrv", "spearman", "n_subtasks", "n_settings"} <= set(m["overall"])
    assert (task["sr_real"], task["sr_imag"], task["abs_delta_sr"], task["n_subtasks"]) == (0.5, 0.5, 0.0, 2)
    T = 1 + SPEC.frames
    assert task["hfr"] == pytest.approx((1 + 5 / T) / 2, abs=1e-6)
    assert task["sr_real_checker"] is not None  # the simulator's checker judged both real branches
    # Two settings whose imagined and real rates agree (1, 0 and 1, 0).
    assert m["overall"]["pearson"] == 1.0 and m["overall"]["mmrv"] == 0.0 and m["overall"]["n_settings"] == 2
    assert m["judges"]["success"] == ["fake_vision"] and m["judges"]["checker"] == ["sim_checker"]
    ss = m["single_step"]
    assert ss["K"] == SPEC.frames and ss["pairs_used"] + ss["pairs_skipped"] == 2
    assert ss["video_mode"] == "lossless"


def test_single_step_figures_per_view_and_frame(run: Path) -> None:
    # The real branch stores the safety-filtered command, which can differ from the chunk in round 0;
    # a loose tolerance admits both pairs so the figures are computed over both.
    ss = compute_run_metrics(run, bootstrap=0, action_atol=1.0)["single_step"]
    assert ss["pairs_used"] == 2 and ss["starts_identical"] == 2
    assert set(ss["per_view"]) == {"cam_high", "cam_left_wrist", "cam_right_wrist"}
    for name in ("psnr", "psnr_pooled", "ssim"):
        assert len(ss["per_frame"][name]) == SPEC.frames
    assert 10 < ss["psnr_pooled"] < 60 and 0 < ss["ssim"] < 1  # a prediction, not a copy of reality
    assert ss["lpips"] is not None or ss["lpips_reason"]
