"""The head view's object checks on the varied look's hard cases: grain of an object's hue in and out of
shadow, objects turning out of view and back, bowls uncovered in pieces, and objects deleted beside a gripper
the image cannot tell from the table (``hallucination_checks._ObjectFrames``).

Each test edits one real episode's scene (stack_blocks, flat look) at a spot by the table's far edge, away
from arms and objects, so a rule is seen to decide alone: without it the same edit is flagged.
"""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from pilworld.config.rig import RigConfig
from pilworld.data.episode import Episode
from pilworld.judges.base import episode_task
from pilworld.judges.hallucination import head_scene
from pilworld.judges.hallucination_checks import HeadScene, Thresholds, _ObjectFrames
from pilworld.judges.hallucination_scene import Shadows
from tests.pilworld.judges.hallucination_data import clean_episodes, sim_rig

T = 20  # the frame edited: the object at the spot is seen at T - 1 and gone at T, or the other way round


@pytest.fixture(scope="module")
def scene(tmp_path_factory: pytest.TempPathFactory) -> HeadScene:
    episodes: list[Episode] = clean_episodes(tmp_path_factory.getbasetemp())
    rig: RigConfig = sim_rig()
    return head_scene(episodes[0], rig, episode_task(episodes[0]), Thresholds())


def _spot(scene: HeadScene, rows: slice = slice(4, 8), cols: slice = slice(60, 64)) -> np.ndarray:
    spot = np.zeros(scene.labels.shape[1:], bool)
    spot[rows, cols] = True
    assert not (scene.labels[T - 3 : T + 2][:, spot] > 0).any() and not scene.arms.whole[T - 3 : T + 2][:, spot].any()
    return spot


def _vanishing(scene: HeadScene, spot: np.ndarray) -> HeadScene:
    """A red object at ``spot`` up to ``T - 1``, table from ``T`` on (the image shows the table there again)."""
    labels, images = scene.labels.copy(), scene.images.copy()
    colourful, table = scene.colourful.copy(), scene.table.copy()
    labels[:T, spot] = 1
    images[:T, spot] = (230, 40, 40)
    colourful[:T, spot] = True
    table[:T, spot] = False
    return dataclasses.replace(scene, labels=labels, images=images, colourful=colourful, table=table)


def _appearing(scene: HeadScene, spot: np.ndarray) -> HeadScene:
    """A red object at ``spot`` from ``T`` on, where the table showed before."""
    labels, images = scene.labels.copy(), scene.images.copy()
    colourful, table = scene.colourful.copy(), scene.table.copy()
    labels[T:, spot] = 1
    images[T:, spot] = (230, 40, 40)
    colourful[T:, spot] = True
    table[T:, spot] = False
    return dataclasses.replace(scene, labels=labels, images=images, colourful=colourful, table=table)


def test_an_object_that_vanishes_onto_table_is_found_and_grain_the_empty_scene_explains_is_not(
    scene: HeadScene,
) -> None:
    """An object seen at ``T - 1`` and table at ``T`` vanished. The same blob where the empty scene (or its shadow)
    already explains it at ``T - 1`` was the table's grain passing the hue test (a warm wood under an orange
    bowl's hue; dark grain in an arm's shadow passes even the saturated test)."""
    th = Thresholds()
    spot = _spot(scene)
    gone = _vanishing(scene, spot)
    found = _ObjectFrames(gone, th).vanished(T, 0)
    assert len(found) == 1 and (found[0] == spot).all()
    table = gone.table.copy()
    table[T - 1, spot] = True
    assert _ObjectFrames(dataclasses.replace(gone, table=table), th).vanished(T, 0) == []
    shadow = gone.shadow.copy()
    shadow[T - 1, spot] = True
    assert _ObjectFrames(dataclasses.replace(gone, shadow=shadow), th).vanished(T, 0) == []


def test_a_shadow_falling_on_grain_is_no_object_vanishing(scene: HeadScene) -> None:
    """Grain taken for an object in every frame (the empty scene never seen there) loses its hue when an arm's
    shadow falls on it: its pixels scaled by the episode's shadow tint and ratio, from three frames before and
    from the frame before, are no object lost. The same blob turning to a table of another colour is."""
    th = Thresholds()
    spot = _spot(scene)
    grain = (150.0, 120.0, 100.0)
    gone = _vanishing(scene, spot)
    images = gone.images.copy()
    images[: T + 2, spot] = grain
    images[T:, spot] = tuple(0.6 * v for v in grain)  # the shadow: every channel × 0.6
    neutral = Shadows(tint=np.full(3, 1.0 / 3.0), ratio=0.6)
    shaded = _ObjectFrames(dataclasses.replace(gone, images=images, shadows=neutral), th)
    assert shaded.shaded(spot, T) and shaded.vanished(T, 0) == []
    unlit = _ObjectFrames(dataclasses.replace(gone, images=images, shadows=None), th)
    assert not unlit.shaded(spot, T)  # a scene without cast shadows excuses nothing
    images[T:, spot] = (60, 120, 90)  # another colour: something went
    other = _ObjectFrames(dataclasses.replace(gone, images=images, shadows=neutral), th)
    assert not other.shaded(spot, T) and len(other.vanished(T, 0)) == 1


def test_an_object_seen_there_two_or_three_frames_before_is_no_new_one(scene: HeadScene) -> None:
    """A ball tipping inside a cup turns out of view for a frame or two and back where it was: no appearance.
    Out of nothing, it is one."""
    th = Thresholds()
    spot = _spot(scene)
    new = _appearing(scene, spot)
    assert len(_ObjectFrames(new, th).appeared(T, 0)) == 1
    labels = new.labels.copy()
    labels[T - 3, spot] = 1
    assert _ObjectFrames(dataclasses.replace(new, labels=labels), th).appeared(T, 0) == []


def test_an_object_uncovered_beside_a_moving_neighbour_is_no_new_one(scene: HeadScene) -> None:
    """A bowl carried over a bowl uncovers the lower one's rim in pieces; a marker turning in the fingers shows a
    new colour where the old was: a blob touching another object that moved off right beside it is explained.
    Beside a neighbour that stays put, or one that appears with it (the bits of a neighbour a copy brings
    along), it is not."""
    th = Thresholds()
    spot = _spot(scene)
    new = _appearing(scene, spot)
    labels = new.labels.copy()
    labels[: T + 2, 4:8, 64:68] = 2  # a neighbour of another colour, touching the spot, still
    still = _ObjectFrames(dataclasses.replace(new, labels=labels), th)
    assert len(still.appeared(T, 0)) == 1
    labels[T - 1, 4:8, 56:60] = 2  # at T - 1 it also lay over the spot's far side: it moved off
    moved = _ObjectFrames(dataclasses.replace(new, labels=labels), th)
    assert moved.beside_moving(spot, T, 0) and moved.appeared(T, 0) == []
    labels[: T - 1, 4:8, 56:68] = 0
    labels[T - 1, 4:8, 56:68] = 0  # the neighbour appears with the blob (a copy brings its neighbour's bits)
    brought = _ObjectFrames(dataclasses.replace(new, labels=labels), th)
    assert not brought.beside_moving(spot, T, 0) and len(brought.appeared(T, 0)) == 1


def test_an_object_in_a_shifted_hue_before_is_revealed_not_new(scene: HeadScene) -> None:
    """An object coming out of an arm's shadow shows a hue outside its class for a frame: saturated pixels there
    at ``T - 1`` mean it was already there."""
    th = Thresholds()
    spot = _spot(scene)
    new = _appearing(scene, spot)
    colourful = new.colourful.copy()
    colourful[T - 1, spot] = True
    assert _ObjectFrames(dataclasses.replace(new, colourful=colourful), th).appeared(T, 0) == []


def test_one_saturated_pixel_does_not_make_grain_an_object(scene: HeadScene) -> None:
    """Camera noise lifts a pixel of a faded speck over the saturated test; a speck stays a speck unless most
    of it is saturated."""
    th = Thresholds()
    spot = _spot(scene)
    images, colourful = scene.images.copy(), scene.colourful.copy()
    images[T, spot] = (200, 150, 150)  # faded red, 16 px
    one = np.zeros_like(spot)
    one[5, 61] = True
    colourful[T, one] = True
    assert _ObjectFrames(dataclasses.replace(scene, images=images, colourful=colourful), th).faint(spot, T)
    colourful[T, spot] = True
    assert not _ObjectFrames(dataclasses.replace(scene, images=images, colourful=colourful), th).faint(spot, T)


def test_where_arm_and_table_look_alike_only_the_drawn_arm_hides(scene: HeadScene) -> None:
    """Over a table of the arm's grey the drawn arm alone is cover: an object under the drawn arm is hidden,
    one beside the fingers (within the margin an arm the image shows gets) is not."""
    th = Thresholds()
    spot = _spot(scene)
    whole = scene.arms.whole.copy()
    whole[T - 1 : T + 2] = 0
    whole[T - 1 : T + 2, 4:8, 64:70] = 1  # an arm drawn right beside the spot
    beside = dataclasses.replace(scene, arms=dataclasses.replace(scene.arms, whole=whole), arm_visibility=0.85)
    table = np.ones_like(scene.table)
    beside = dataclasses.replace(beside, table=table, known=np.ones_like(scene.known))
    of = _ObjectFrames(beside, th)
    assert of.arm_unseen and not of.hidden_or_seen(spot, T, 0, tight=True)
    assert of.hidden_or_seen(spot, T, 0)  # what comes out from beside an arm moving away: its margin hides
    whole[T - 1 : T + 2, 4:8, 58:70] = 1  # drawn over it
    over = _ObjectFrames(dataclasses.replace(beside, arms=dataclasses.replace(scene.arms, whole=whole)), th)
    assert over.hidden_or_seen(spot, T, 0, tight=True)


def test_what_lay_beneath_all_along_hides_nothing(scene: HeadScene) -> None:
    """A puck deleted from its coaster shows the coaster where it was: the coaster never moved (it left no pixels
    behind), so it uncovered the spot rather than hid it. An object that came over the spot, leaving pixels on
    its trailing side, hides it."""
    th = Thresholds()
    spot = _spot(scene)
    gone = _vanishing(scene, spot)
    labels = gone.labels.copy()
    labels[T - 3 : T + 2, 2:10, 58:66] = 2  # a coaster around the spot, all along
    labels[:T, spot] = 1  # the puck on it until T - 1
    table = gone.table.copy()
    table[T:, spot] = False  # where the puck was, the coaster shows: not table
    beneath = _ObjectFrames(dataclasses.replace(gone, labels=labels, table=table), th)
    assert beneath.still_beneath(spot, T, 0) == frozenset({1})
    assert not beneath.hidden_or_seen(spot, T, 0, still=beneath.still_beneath(spot, T, 0))
    labels[T - 3 : T, 2:10, 58:66] = 0
    labels[T - 3 : T, 2:10, 52:58] = 2  # the other object was beside the spot and slid over it at T
    labels[:T, spot] = 1
    over = _ObjectFrames(dataclasses.replace(gone, labels=labels, table=table), th)
    assert over.still_beneath(spot, T, 0) == frozenset()
    assert over.hidden_or_seen(spot, T, 0, still=over.still_beneath(spot, T, 0))


def test_the_table_grain_of_an_objects_hue_beside_it_does_not_keep_it_there(scene: HeadScene) -> None:
    """A warm wood's grain can share an object's hue: faded specks of its class beside a vanished object are not
    the object still there, or a deletion beside them goes unseen. Faded pixels where the object itself was are
    (an object fading in place, into a shadow or behind a finger), and so are saturated ones beside it."""
    th = Thresholds()
    spot = _spot(scene)
    gone = _vanishing(scene, spot)
    labels, images = gone.labels.copy(), gone.images.copy()
    grain = np.zeros_like(spot)
    grain[4:8, 65:67] = True  # 8 px of faded red grain a pixel from the object, in every frame
    labels[:, grain] = 1
    images[:, grain] = (200, 150, 150)
    beside = dataclasses.replace(gone, labels=labels, images=images)
    assert grain.sum() >= 0.25 * spot.sum()  # counted as the object, the grain would keep it "there"
    assert len(_ObjectFrames(beside, th).vanished(T, 0)) == 1
    fading = labels.copy()
    fading[T, 5:7, 61:63] = 1  # 4 of its 16 px still of its hue, faded, where it was
    images_fading = images.copy()
    images_fading[T, 5:7, 61:63] = (200, 150, 150)
    assert _ObjectFrames(dataclasses.replace(beside, labels=fading, images=images_fading), th).vanished(T, 0) == []
    colourful = beside.colourful.copy()
    colourful[:, grain] = True  # saturated beside it: the object, moved a step
    images[:, grain] = (230, 40, 40)
    moved = dataclasses.replace(beside, images=images, colourful=colourful)
    assert _ObjectFrames(moved, th).vanished(T, 0) == []
