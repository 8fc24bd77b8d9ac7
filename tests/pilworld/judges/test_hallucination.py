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


def test_a_lit_wrist_gripper_alone_is_no_swapped_view(episodes: list[Episode], rig: RigConfig) -> None:
    """A tinted key light lights up to half of a wrist view's own gripper (docs/judges.md, "Under the varied
    look"): that alone is no cross-view conflict; a gripper three-quarters gone is."""
    from pilworld.judges.hallucination import head_scene
    from pilworld.judges.hallucination_checks import Thresholds, check_views, wrist_signature

    ep, th, view = episodes[1], Thresholds(), "cam_left_wrist"
    scene = head_scene(ep, rig, episode_task(ep), th)
    sig = wrist_signature(ep.images[view], th.signature_dark)
    assert sig.sum() >= 20

    def lit(share: float) -> np.ndarray:
        frames = ep.images[view].copy()
        rows, cols = np.nonzero(sig)
        n = int(share * len(rows))
        frames[30:, rows[:n], cols[:n]] = 170  # the top of the gripper, lit from frame 30 on
        return frames

    assert check_views(scene, {view: lit(0.55)}, th) is None
    found = check_views(scene, {view: lit(0.8)}, th)
    assert found is not None and found.frame == 30 and found.category == "cross-view conflict", found


def test_the_head_views_own_arm_over_a_wrist_signature_is_no_swapped_view(
    episodes: list[Episode], rig: RigConfig
) -> None:
    """The head view "shows a wrist view's gripper" when the pixels at that gripper's place in the wrist image turn
    dark. Its own arm moving over them darkens them too: only pixels away from the drawn arms count. The same
    darkness away from the arms is a wrist image in the head view."""
    from pilworld.judges.hallucination import head_scene
    from pilworld.judges.hallucination_checks import Thresholds, check_views, wrist_signature

    ep, th, view = episodes[1], Thresholds(), "cam_left_wrist"
    scene = head_scene(ep, rig, episode_task(ep), th)
    sig = wrist_signature(ep.images[view], th.signature_dark)
    images, whole = scene.images.copy(), scene.arms.whole.copy()
    rows, cols = np.nonzero(sig)
    n = int(0.75 * len(rows))
    images[30:, rows[:n], cols[:n]] = 20  # three quarters of the signature dark in the head view from 30 on ...
    whole[30:, rows[:n], cols[:n]] = 1  # ... where an arm is drawn
    armed = dataclasses.replace(scene, images=images, arms=dataclasses.replace(scene.arms, whole=whole))
    base = check_views(scene, {view: ep.images[view]}, th)
    assert base is None, base
    assert check_views(armed, {view: ep.images[view]}, th) is None
    images[30:, rows, cols] = 20  # the whole signature dark, half of it away from the arms: a wrist image
    whole = scene.arms.whole.copy()
    whole[30:, rows[: n // 2], cols[: n // 2]] = 1
    shown = dataclasses.replace(armed, images=images, arms=dataclasses.replace(scene.arms, whole=whole))
    found = check_views(shown, {view: ep.images[view]}, th)
    assert found is not None and found.frame == 30 and "shows cam_left_wrist" in found.reason, found


def test_the_table_colour_does_not_call_a_drawn_arm_table(episodes: list[Episode], rig: RigConfig) -> None:
    """Where the empty scene was never seen (an object always sat there) the table's colour is the rule, but not
    under a drawn arm: an arm of the table's grey would otherwise hide nothing and an object under it vanish."""
    from pilworld.judges.hallucination import head_scene
    from pilworld.judges.hallucination_checks import Thresholds, _ObjectFrames

    ep, th = episodes[0], Thresholds()
    scene = head_scene(ep, rig, episode_task(ep), th)
    t = int(np.argmax(scene.arms.whole.reshape(scene.length, -1).sum(axis=1)))
    everywhere = np.ones_like(scene.table_colour)
    unseen = _ObjectFrames(dataclasses.replace(scene, table_colour=everywhere, known=np.zeros_like(scene.known)), th)
    drawn = scene.arms.whole[t] > 0
    assert drawn.any() and not unseen.table(t)[drawn].any() and unseen.table(t)[~drawn].all()
    seen = _ObjectFrames(dataclasses.replace(scene, table=everywhere, known=np.ones_like(scene.known)), th)
    assert seen.table(t).all()  # compared with the seen empty scene, a pixel under a drawn arm can be table


def test_an_object_a_gripper_acts_on_may_move_fast(episodes: list[Episode], rig: RigConfig) -> None:
    """A gripper opening or closing on an object may squeeze it out, drop it or let it go faster than a step:
    a blob near it that vanishes with something coloured seen close by, or appears out from under it, is
    explained; with the gripper's opening unchanged, or far from the gripper, it is not."""
    from pilworld.judges.hallucination import head_scene
    from pilworld.judges.hallucination_checks import Thresholds, _ObjectFrames

    ep, th = episodes[0], Thresholds()
    scene = head_scene(ep, rig, episode_task(ep), th)
    t, H, W = 30, scene.images.shape[1], scene.images.shape[2]
    gripper = np.zeros_like(scene.arms.gripper)
    gripper[1, t - 1 : t + 1, 40:50, 60:70] = 1
    blob = np.zeros((H, W), bool)
    blob[52:56, 62:66] = True  # just below the fingers
    labels = scene.labels.copy()
    labels[t] = 0
    labels[t, 62:66, 62:66] = 1  # where it landed, 10 px lower
    grip = scene.grip.copy()
    grip[:, 1] = 1.0
    closing = grip.copy()
    closing[t - 2 : t + 1, 1] = (0.3, 0.15, 0.0)
    colourless = np.zeros_like(scene.colourful)

    def frames(g: np.ndarray, seen: np.ndarray = labels) -> _ObjectFrames:
        arms = dataclasses.replace(scene.arms, gripper=gripper)
        return _ObjectFrames(dataclasses.replace(scene, arms=arms, labels=seen, grip=g, colourful=colourless), th)

    assert frames(closing).gripper_acting(blob, t, seen_after=True)
    assert not frames(grip).gripper_acting(blob, t, seen_after=True)  # the opening does not change
    far = np.roll(blob, 40, axis=1)
    assert not frames(closing).gripper_acting(far, t)
    gone = labels.copy()
    gone[t : t + 2] = 0
    nothing = frames(closing, gone)
    assert not nothing.gripper_acting(blob, t, seen_after=True)  # gone, and seen nowhere near: not explained
    assert nothing.gripper_acting(blob, t)  # out from under the gripper (an object that appeared)


def test_a_colour_test_that_flickers_where_the_image_does_not_change_is_no_object(
    episodes: list[Episode], rig: RigConfig
) -> None:
    """A sand-coloured table's grains pass an object's hue test now and then with camera noise: a blob that comes
    or goes where the image stays the same (or the empty scene explains it) is no object; one painted in is."""
    from pilworld.judges.hallucination import head_scene
    from pilworld.judges.hallucination_checks import Thresholds, _ObjectFrames

    ep, th = episodes[0], Thresholds()
    scene = head_scene(ep, rig, episode_task(ep), th)
    t = 20
    spot = np.zeros(scene.labels.shape[1:], bool)
    spot[4:8, 60:64] = True  # by the far edge of the table, away from arms and objects
    assert not (scene.labels[t - 1][spot] > 0).any() and not scene.arms.whole[t - 1 : t + 1, spot].any()
    labels = scene.labels.copy()
    labels[t:, spot] = 1  # the colour test says "object" from t on, the image is unchanged
    flicker = _ObjectFrames(dataclasses.replace(scene, labels=labels), th)
    assert flicker.appeared(t, 0) == []
    images = scene.images.copy()
    images[t:, spot] = (230, 40, 40)  # now something red is there
    table = scene.table.copy()
    table[t:, spot] = False
    colourful = scene.colourful.copy()
    colourful[t:, spot] = True
    painted = _ObjectFrames(
        dataclasses.replace(scene, labels=labels, images=images, table=table, colourful=colourful), th
    )
    found = painted.appeared(t, 0)
    assert len(found) == 1 and (found[0] == spot).all()


def test_a_faint_speck_of_an_objects_hue_is_no_object(episodes: list[Episode], rig: RigConfig) -> None:
    """A warm wood table's grain passes the faded colour test by a hair and drops out of it with noise or a shadow:
    a small blob of faded pixels only comes and goes without counting; the same blob, saturated, is an object."""
    from pilworld.judges.hallucination import head_scene
    from pilworld.judges.hallucination_checks import Thresholds, _ObjectFrames

    ep, th = episodes[0], Thresholds()
    scene = head_scene(ep, rig, episode_task(ep), th)
    t = 20
    spot = np.zeros(scene.labels.shape[1:], bool)
    spot[4:8, 60:64] = True  # 16 px by the far edge of the table, away from arms and objects
    labels, images, table = scene.labels.copy(), scene.images.copy(), scene.table.copy()
    labels[t:, spot] = 1
    images[t:, spot] = (200, 150, 150)  # a faded red: saturation 0.25
    table[t:, spot] = False
    faint = _ObjectFrames(dataclasses.replace(scene, labels=labels, images=images, table=table), th)
    assert faint.faint(spot, t) and faint.appeared(t, 0) == []
    colourful = scene.colourful.copy()
    colourful[t:, spot] = True  # saturated throughout: an object
    solid = _ObjectFrames(
        dataclasses.replace(scene, labels=labels, images=images, table=table, colourful=colourful), th
    )
    assert not solid.faint(spot, t) and len(solid.appeared(t, 0)) == 1
    big = np.zeros_like(spot)
    big[4:10, 58:64] = True  # 36 px, saturation 0.25: grain, passing the faded test by a hair
    images[t:, big] = (200, 150, 150)
    grain = _ObjectFrames(dataclasses.replace(scene, images=images), th)
    assert grain.faint(big, t)
    images[t:, big] = (200, 144, 144)  # saturation 0.28: short of saturated, well over faded: a washed-out object
    assert not _ObjectFrames(dataclasses.replace(scene, images=images), th).faint(big, t)


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
    """Acceptance (docs/judges.md): frame k ± 1 found in ≥ 90 % of faulted real episodes, ≤ 5 % of clean ones flagged.

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
    assert report["clean"]["false_positive_rate"] <= 0.05


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
