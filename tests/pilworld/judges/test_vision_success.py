"""The image-only success judge against the simulator's privileged checker (docs/judges.md)."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import replace
from pathlib import Path
from typing import Any

import cv2
import numpy as np
import pytest

from pilworld.config.rig import RigConfig
from pilworld.data.episode import Episode
from pilworld.judges.base import Judge, JudgeContext
from pilworld.judges.vision_success import VisionSuccessJudge
from pilworld.perception.views import label_image
from pilworld.reference.paper_tasks import TASK_SPECS
from pilworld.types import ChunkSpec
from tests.conftest import SIM_RIG

# (task, checkpoint, seed, subtask) → what the checker says; chosen away from its tolerance edges.
CASES = [
    ("sort_cubes", "scripted_step_30k", 7, 0, True),
    ("sort_cubes", "scripted_step_01k", 10, 0, False),  # still held at the end
    ("sort_cubes", "scripted_step_01k", 9, 0, False),
    ("stack_bowls", "scripted_step_30k", 7, 0, True),
    ("stack_bowls", "scripted_step_30k", 7, 1, True),
    ("stack_bowls", "scripted_step_01k", 7, 0, False),
    ("stack_blocks", "scripted_step_30k", 7, 0, True),
    ("stack_blocks", "scripted_step_30k", 7, 1, True),
    ("stack_blocks", "scripted_step_01k", 9, 0, False),
]


@pytest.fixture(scope="module")
def rig() -> RigConfig:
    return RigConfig.load(SIM_RIG)


def _rollout(robot: Any, checkpoint: str, seed: int, subtask: int) -> tuple[Episode, bool, str]:
    """One subtask from its laid-out start, recorded like ``pilworld sim collect`` does (frames at stride Δ)."""
    from pilworld.collection.rollout import run_subtask
    from pilworld.policies.scripted import ScriptedPolicy

    spec = ChunkSpec()
    policy = ScriptedPolicy(robot.rig, checkpoint, horizon=spec.horizon)
    policy.reset(seed=seed * 100)
    start = robot.reset(seed=seed, subtask=subtask, history=spec.history, stride=spec.stride)
    rec = run_subtask(robot, policy.infer, start.observation, robot.task.instruction, spec=spec, subtask_index=subtask)
    assert rec.check is not None
    episode = Episode(
        images={v: np.stack(frames) for v, frames in rec.images.items()},
        state=np.stack(rec.states).astype(np.float32),
        action=np.stack(rec.actions).astype(np.float32),
        task=robot.task.instruction,
        subtask_index=subtask,
        checkpoint=checkpoint,
        seed=seed,
        round_index=np.asarray(rec.rounds, dtype=np.int64),
        extra={"sim_task": robot.task.name},
    )
    return episode, rec.check.success, rec.check.reason


@pytest.fixture(scope="module")
def episodes(robots: Callable[[str], Any]) -> list[tuple[str, Episode, bool, str]]:
    """Each case's episode (arrays only, detached from the simulator), checker verdict and reason."""
    out = []
    for task, checkpoint, seed, subtask, expected in CASES:
        episode, success, reason = _rollout(robots(task), checkpoint, seed, subtask)
        assert success == expected, f"{task} {checkpoint} seed {seed}: the checker now says {reason!r}"
        out.append((task, episode, success, reason))
    return out


def _judge(episode: Episode, rig: RigConfig, task: str, judge: Judge | None = None) -> Any:
    return (judge or VisionSuccessJudge()).judge(episode, JudgeContext(rig=rig, task=task))


def test_judge_contract() -> None:
    judge = VisionSuccessJudge()
    assert isinstance(judge, Judge)
    assert judge.judge_id == "vision_success"
    assert judge.kind == "vision"
    with pytest.raises(ValueError, match="window"):
        VisionSuccessJudge(window=0)


def test_agrees_with_the_checker_on_successes_and_failures(
    episodes: list[tuple[str, Episode, bool, str]], rig: RigConfig
) -> None:
    for task in TASK_SPECS:
        assert {s for t, _, s, _ in episodes if t == task} == {True, False}, f"{task} needs both outcomes"
    for task, episode, success, reason in episodes:
        verdict = _judge(episode, rig, task)
        assert verdict.success is success, f"{task} subtask {episode.subtask_index}: checker {reason!r}, {verdict}"
        assert verdict.first_hallucination_frame is None
        assert verdict.reason


def test_still_held_is_a_failure_with_that_reason(
    episodes: list[tuple[str, Episode, bool, str]], rig: RigConfig
) -> None:
    held = [(t, e) for t, e, _, r in episodes if "still held" in r]
    assert held
    for task, episode in held:
        assert "still held" in _judge(episode, rig, task).reason


def _successes(episodes: list[tuple[str, Episode, bool, str]]) -> list[tuple[str, Episode]]:
    return [(t, e) for t, e, s, _ in episodes if s]


def test_rewound_ending_is_a_failure(episodes: list[tuple[str, Episode, bool, str]], rig: RigConfig) -> None:
    """The last second replaced by the first frame (images and state): the object is back where it started."""
    for task, episode in _successes(episodes):
        n = 10
        images = {v: f.copy() for v, f in episode.images.items()}
        for f in images.values():
            f[-n:] = f[0]
        state = episode.state.copy()
        state[-n:] = state[0]
        doctored = replace(episode, images=images, state=state)
        verdict = _judge(doctored, rig, task)
        assert verdict.success is False, f"{task} subtask {episode.subtask_index}: {verdict}"


def test_goal_object_painted_out_is_a_failure(episodes: list[tuple[str, Episode, bool, str]], rig: RigConfig) -> None:
    """The subtask's object painted over with the table colour in every view of the last frames."""
    for task, episode in _successes(episodes):
        spec = TASK_SPECS[task]
        target = spec.goal(episode.subtask_index).target
        images = {v: f.copy() for v, f in episode.images.items()}
        table = np.array([190, 182, 165], dtype=np.uint8)  # the table's beige as rendered
        for frames in images.values():
            for t in range(episode.length - 30, episode.length):
                mask = label_image(frames[t], spec.classes).masks[target].astype(np.uint8)
                frames[t][cv2.dilate(mask, np.ones((3, 3), np.uint8)) > 0] = table
        verdict = _judge(replace(episode, images=images), rig, task)
        assert verdict.success is False, f"{task} subtask {episode.subtask_index}: {verdict}"


def test_reads_no_privileged_state(
    episodes: list[tuple[str, Episode, bool, str]], rig: RigConfig, monkeypatch: pytest.MonkeyPatch
) -> None:
    """An Episode alone: no simulator call, no stored extras, the task named by the context or the instruction."""
    from simrig.robot import SimRobot

    def forbidden(*_: Any, **__: Any) -> Any:
        raise AssertionError("the image-only judge read simulator state")

    for name in ("object_poses", "task_state", "check_subtask", "held_by", "state", "render", "observe"):
        monkeypatch.setattr(SimRobot, name, forbidden)
    for _, episode, success, _ in episodes:
        bare = replace(episode, extra={}, seed=0, checkpoint="")
        assert _judge(bare, rig, "").success is success  # the task known from the instruction alone


def test_commanded_state_as_in_the_imagined_branch(
    episodes: list[tuple[str, Episode, bool, str]], rig: RigConfig
) -> None:
    """Imagined episodes store the commanded state (the last stride-aligned action), not a measured one."""
    for task, episode, success, reason in episodes:
        commanded = episode.state.copy()
        commanded[1:] = episode.action[:-1]
        imagined = replace(episode, state=commanded, origin="imagined")
        verdict = _judge(imagined, rig, task)
        assert verdict.success is success, f"{task} subtask {episode.subtask_index}: checker {reason!r}, {verdict}"


def test_unknown_task_abstains_and_missing_head_view_is_refused(
    episodes: list[tuple[str, Episode, bool, str]], rig: RigConfig
) -> None:
    task, episode, _, _ = episodes[0]
    # A task the hand-written reference judge was not written for: no success verdict, not an error.
    unknown = _judge(replace(episode, task="fold the towel."), rig, "fold_towel")
    assert unknown.success is None and "paper's tasks" in unknown.reason
    with pytest.raises(ValueError, match="subtask_index"):
        _judge(replace(episode, subtask_index=7), rig, task)
    wrists = {v: f for v, f in episode.images.items() if v != "cam_high"}
    with pytest.raises(ValueError, match="cam_high"):
        _judge(replace(episode, images=wrists), rig, task)


def test_bench_on_a_collected_store(tmp_path: Path, rig: RigConfig) -> None:
    """``run_judge_bench`` over a stored (h264) collection: the report's shape and its agreement."""
    from pilworld.bench.judges import run_judge_bench
    from pilworld.collection.collect import collect

    root = tmp_path / "store"
    collect(
        root,
        rig_path=str(SIM_RIG),
        tasks=["stack_blocks"],
        checkpoints=["scripted_step_30k"],
        episodes=1,
        seed0=7,
        workers=1,
        progress=False,
    )
    report = run_judge_bench(root, rig)
    assert report["n"] == 2  # the run's two subtasks
    assert set(report["per_task"]) == {"stack_blocks"}
    confusion = report["per_task"]["stack_blocks"]["confusion"]
    assert sum(confusion.values()) == 2
    assert report["agreement"] == (confusion["tp"] + confusion["tn"]) / 2 == 1.0
    assert len(report["disagreements"]) == confusion["fp"] + confusion["fn"]
    assert report["seconds_per_episode"] > 0
    with pytest.raises(ValueError, match="no real-branch"):
        run_judge_bench(root, rig, episodes=[])


@pytest.mark.slow
@pytest.mark.timeout(1800)  # 240 simulated subtasks and their judging: > 600 s (the suite's default) on this machine
def test_acceptance_on_fresh_seeds(tmp_path: Path, rig: RigConfig) -> None:
    """Acceptance (docs/judges.md):
    ≥ 95 % agreement with the checker on ≥ 100 real-branch subtasks of seeds reserved for judge
    validation — the two fresh sets of docs/judges.md (3,000,100+ and 3,000,200+, 240 subtasks) pooled;
    3,000,000–3,000,002 were looked at while the judge was developed and are not used."""
    from pilworld.bench.judges import run_judge_bench
    from pilworld.collection.collect import collect

    agree = n = 0
    for seed0 in (3_000_100, 3_000_200):
        root = tmp_path / f"judge_val_{seed0}"
        collect(
            root,
            rig_path=str(SIM_RIG),
            tasks=list(TASK_SPECS),
            checkpoints=[f"scripted_step_{s}" for s in ("01k", "02k", "05k", "10k", "30k")],
            episodes=3,
            seed0=seed0,
            workers=2,
            progress=False,
        )
        report = run_judge_bench(root, rig, workers=2)
        n += report["n"]
        agree += round(report["agreement"] * report["n"])
        for task in ("sort_cubes", "stack_blocks"):  # every disagreement so far was a nested bowl
            assert report["per_task"][task]["agreement"] >= 0.95, report["disagreements"]
    assert n >= 100
    assert agree / n >= 0.95, f"{agree} of {n}"
