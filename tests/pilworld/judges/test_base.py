"""judge_dataset: verdicts recorded per episode, in parallel processes, kept when a pass is interrupted."""

from __future__ import annotations

from pathlib import Path

import pytest

from pilworld.config.rig import RigConfig
from pilworld.data.episode import Episode
from pilworld.data.outcomes import JudgeKind, read_outcomes
from pilworld.data.spec import DatasetSpec
from pilworld.data.writer import EpisodeWriter
from pilworld.judges.base import JudgeContext, Verdict, judge_dataset, unjudged_episodes
from tests.pilworld.data.conftest import VIEWS, make_episode

SIM = "configs/rig/sim_dual_ur5e.yaml"


class SeedParity:
    """Success when the episode's seed is even; a hallucination at frame 3 on imagined episodes.

    Module-level (picklable), so it runs in spawned worker processes too.
    """

    judge_id = "parity"
    kind: JudgeKind = "vision"

    def judge(self, episode: Episode, context: JudgeContext) -> Verdict:
        hallucination = 3 if episode.origin == "imagined" else None
        return Verdict(success=episode.seed % 2 == 0, first_hallucination_frame=hallucination)


class Crashing(SeedParity):
    """Fails on the episode with seed 105, after the earlier ones were judged."""

    def judge(self, episode: Episode, context: JudgeContext) -> Verdict:
        if episode.seed == 105:
            raise RuntimeError("judge crashed")
        return super().judge(episode, context)


@pytest.fixture(scope="module")
def dataset(tmp_path_factory: pytest.TempPathFactory) -> Path:
    root = tmp_path_factory.mktemp("judged") / "ds"
    spec = DatasetSpec(video_mode="lossless", views={v: (32, 48) for v in VIEWS})
    with EpisodeWriter(root, spec) as w:
        for k in range(8):
            w.append(make_episode(12, k, origin=("real", "imagined")[k % 2]))
    return root


def _expected() -> list[tuple[int, bool, int | None]]:
    return [(k, (100 + k) % 2 == 0, 3 if k % 2 else None) for k in range(8)]


@pytest.mark.parametrize("workers", [1, 2])
def test_verdicts_recorded_in_one_or_two_processes(dataset: Path, tmp_path: Path, workers: int) -> None:
    import shutil

    root = tmp_path / "ds"
    shutil.copytree(dataset, root)
    rig = RigConfig.load(SIM)
    out = judge_dataset(root, [SeedParity()], rig, workers=workers, flush_every=3)
    got = [(o.episode_index, o.success, o.first_hallucination_frame) for o in out]
    assert got == _expected()
    stored = sorted((o.episode_index, o.success, o.first_hallucination_frame) for o in read_outcomes(root))
    assert stored == got
    assert unjudged_episodes(root, "parity") == []


def test_an_interrupted_pass_keeps_its_flushed_verdicts_and_resumes(dataset: Path, tmp_path: Path) -> None:
    import shutil

    root = tmp_path / "ds"
    shutil.copytree(dataset, root)
    rig = RigConfig.load(SIM)
    with pytest.raises(RuntimeError, match="judge crashed"):
        judge_dataset(root, [Crashing()], rig, workers=1, flush_every=2)
    # Episodes 0-3 were flushed on the way; episode 4's pending verdict is written as the error leaves.
    assert unjudged_episodes(root, "parity") == [5, 6, 7]
    judge_dataset(root, [SeedParity()], rig, episodes=unjudged_episodes(root, "parity"))
    stored = sorted((o.episode_index, o.success, o.first_hallucination_frame) for o in read_outcomes(root))
    assert stored == _expected()


def test_unknown_episodes_and_bad_flush_are_rejected(dataset: Path) -> None:
    rig = RigConfig.load(SIM)
    with pytest.raises(ValueError, match=r"episodes: \[8\] not in"):
        judge_dataset(dataset, [SeedParity()], rig, episodes=[0, 8])
    with pytest.raises(ValueError, match="flush_every"):
        judge_dataset(dataset, [SeedParity()], rig, flush_every=0)
