"""The automatic hallucination detector: each injected fault is found at frame k ± 1 under its category,
clean episodes are not flagged, and (slow) the acceptance (docs/judges.md) on fresh episodes."""

from __future__ import annotations

import dataclasses
import json
from pathlib import Path

import numpy as np
import pytest

from pilworld.config.rig import RigConfig
from pilworld.data.episode import Episode
from pilworld.judges.base import Judge, JudgeContext, Verdict, episode_task
from pilworld.judges.faults import FAULTS
from pilworld.judges.hallucination import CATEGORIES, HallucinationDetector, find_hallucinations
from pilworld.types import HEAD_VIEW
from tests.pilworld.judges.hallucination_data import SIM, clean_episodes, sim_rig

EXPECTED = {
    "delete_object": "object disappearing",
    "duplicate_object": "object appearing",
    "swap_views": "cross-view conflict",
    "teleport_arm": "discontinuous arm motion",
}


@pytest.fixture(scope="module")
def episodes(tmp_path_factory: pytest.TempPathFactory) -> list[Episode]:
    return clean_episodes(tmp_path_factory.getbasetemp())


@pytest.fixture(scope="module")
def rig() -> RigConfig:
    return sim_rig()


def _judge(ep: Episode, rig: RigConfig, task: str | None = None) -> Verdict:
    return HallucinationDetector().judge(ep, JudgeContext(rig=rig, task=episode_task(ep) if task is None else task))


def test_the_detector_is_a_vision_judge() -> None:
    d = HallucinationDetector()
    assert isinstance(d, Judge)
    assert d.judge_id == "auto_hallucination" and d.kind == "vision"
    assert set(EXPECTED.values()) <= set(CATEGORIES)


def test_clean_episodes_are_not_flagged(episodes: list[Episode], rig: RigConfig) -> None:
    for ep in episodes:
        v = _judge(ep, rig)
        assert v.success is None
        assert v.first_hallucination_frame is None, v.reason


@pytest.mark.parametrize("fault", FAULTS)
def test_each_fault_is_found_at_its_frame_under_its_category(
    fault: str, episodes: list[Episode], rig: RigConfig
) -> None:
    from pilworld.bench.hallucination import inject_random

    rng = np.random.default_rng(11)
    judged = 0
    for ep in episodes:
        case = inject_random(fault, ep, rig, rng)
        if case is None:
            continue
        faulted, k = case
        v = _judge(faulted, rig)
        assert v.success is None
        assert v.first_hallucination_frame is not None, f"{fault} at {k} missed"
        assert abs(v.first_hallucination_frame - k) <= 1, (k, v)
        assert v.reason.startswith(EXPECTED[fault] + ": "), v.reason
        judged += 1
    assert judged >= 1


def test_without_object_colours_the_arm_and_view_checks_still_run(episodes: list[Episode], rig: RigConfig) -> None:
    from pilworld.judges.faults import swap_views

    ep = dataclasses.replace(episodes[1], task="do something else", extra={})
    assert _judge(ep, rig, task="").first_hallucination_frame is None
    v = _judge(swap_views(ep, 40), rig, task="")
    assert v.first_hallucination_frame in (39, 40, 41) and v.reason.startswith("cross-view conflict")


def test_findings_are_ordered_and_name_a_category(episodes: list[Episode], rig: RigConfig) -> None:
    from pilworld.judges.faults import delete_object, swap_views, visible_objects

    ep = episodes[0]
    k = next(k for k in range(20, 60) if visible_objects(ep, k - 1))
    both = swap_views(delete_object(ep, k), k + 10)
    found = find_hallucinations(both, rig, episode_task(ep))
    assert [f.frame for f in found] == sorted(f.frame for f in found)
    assert all(f.category in CATEGORIES for f in found)
    assert abs(found[0].frame - k) <= 1


def test_bad_episodes_are_refused(episodes: list[Episode], rig: RigConfig) -> None:
    ep = episodes[0]
    no_head = dataclasses.replace(ep, images={v: f for v, f in ep.images.items() if v != HEAD_VIEW})
    with pytest.raises(ValueError, match=HEAD_VIEW):
        _judge(no_head, rig)
    small = dataclasses.replace(ep, images={v: f[:, ::2, ::2] for v, f in ep.images.items()})
    with pytest.raises(ValueError, match="head camera"):
        _judge(small, rig)


@pytest.mark.slow
@pytest.mark.timeout(3600)
def test_acceptance_on_fresh_seeds(tmp_path: Path) -> None:
    """Acceptance (docs/judges.md): frame k ± 1 found in ≥ 90 % of faulted real episodes, ≤ 10 % of clean ones flagged.

    Seeds 4,000,000+ are reserved for this measurement (never used to tune the detector):
    ``pilworld sim collect --task all --checkpoint all --episodes 2 --seed 4000000`` — 80 episodes.
    """
    from pilworld.bench.hallucination import run_hallucination_bench
    from pilworld.collection.collect import collect
    from pilworld.policies.scripted import CHECKPOINTS
    from simrig.tasks import TASK_NAMES

    root = tmp_path / "halluc_val"
    collect(
        root,
        rig_path=str(SIM),
        tasks=list(TASK_NAMES),
        checkpoints=[c.name for c in CHECKPOINTS],
        episodes=2,
        seed0=4_000_000,
        workers=2,
        progress=False,
    )
    report = run_hallucination_bench(root, SIM, seed=0)
    print(json.dumps({k: report[k] for k in ("clean", "faults", "overall", "seconds_per_episode")}, indent=1))
    assert report["episodes"] >= 60
    assert report["overall"]["detection_rate"] >= 0.90
    for fault, stats in report["faults"].items():
        assert stats["n"] >= 30, fault
        assert stats["detection_rate"] >= 0.90, (fault, stats)
    assert report["clean"]["false_positive_rate"] <= 0.10


@pytest.mark.slow  # two varied-look subtasks simulated (~40 s): shadow-casting light, textured table
def test_the_varied_look_is_explained_by_the_empty_scene(tmp_path: Path, rig: RigConfig) -> None:
    """Under the varied look (a textured table, a tinted shadow-casting light) clean episodes are not flagged
    (docs/judges.md: with one table colour the detector flagged 48 of 50 such episodes as arm motion; the
    bench there has every fault's recall on that look)."""
    episodes = clean_episodes(tmp_path, appearance="varied", seed=4_300_000)
    assert len(episodes) == 2
    for ep in episodes:
        v = _judge(ep, rig)
        assert v.first_hallucination_frame is None, v.reason
