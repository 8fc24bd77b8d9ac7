"""Objects vanishing from a wrist view (hallucination_wrist): what a gripper holds and what it lets go of.

The head view is a real episode with an object deleted at ``k`` (``faults.delete_object``); the left wrist view
is drawn here — a grey table, the gripper dark at the foot, one blob of the deleted object's colour — as the
real left arm moves: a blob resting on the table follows the camera's motion, a held one stays put in the image.
"""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from numpy.typing import NDArray

from pilworld.config.rig import RigConfig
from pilworld.data.episode import Episode
from pilworld.judges.faults import delete_object, visible_objects
from pilworld.judges.hallucination import head_scene
from pilworld.judges.hallucination_checks import OBJECT_DISAPPEARED, Finding, Thresholds
from pilworld.judges.hallucination_wrist import PLANE_Z, WristCamera, check_wrist_objects
from pilworld.types import LEFT_GRIP, RIGHT_GRIP
from tests.pilworld.judges.hallucination_data import clean_episodes, sim_rig

VIEW = "cam_left_wrist"
TABLE = (150, 150, 150)
TRAY = (120, 90, 60)  # a brown that is neither the table nor the object: something in front, or what was behind
FAR = (64, 35)  # (u, v): high in the view, away from the fingers
BETWEEN = (64, 100)  # between the fingers, where a held object sits


@pytest.fixture(scope="module")
def rig() -> RigConfig:
    return sim_rig()


@pytest.fixture(scope="module")
def deleted(tmp_path_factory: pytest.TempPathFactory, rig: RigConfig) -> tuple[Episode, int, str]:
    """A clean episode with an object deleted at a frame where the right gripper is open and the left camera's
    view of the table moves 8–30 px at :data:`FAR` (so "where it was in the image" and "where the table took it"
    are different places)."""
    ep = clean_episodes(tmp_path_factory.getbasetemp())[0]
    cam = WristCamera.from_rig(rig, VIEW)
    poses = cam.poses(rig, ep.state)
    for k in range(20, ep.length - 5):
        if ep.state[k - 2 : k + 2, RIGHT_GRIP].min() < 0.9:
            continue
        uv, ok = cam.reproject(np.array([FAR], float), poses[k - 1], poses[k], PLANE_Z)
        if not ok.all() or not 8 <= float(np.hypot(*(uv[0] - FAR))) <= 30:
            continue
        seen = visible_objects(ep, k - 1)
        if seen:
            name = max(seen, key=lambda n: seen[n])
            return delete_object(ep, k, name), k, name
    raise AssertionError("no frame with an object in view, the right gripper open and the left camera moving")


def _wrist(
    ep: Episode,
    k: int,
    name: str,
    rig: RigConfig,
    held: bool,
    paint: tuple[int, int, int],
    landed: tuple[int, int] | None = None,
) -> NDArray[np.uint8]:
    """(T, H, W, 3): the object's blob until ``k`` — on the table where :data:`FAR` shows it at ``k - 1``, or
    held between the fingers at :data:`BETWEEN` — then gone, ``paint`` in the image where it was at ``k - 1``
    (and, with ``landed``, the blob shown there from ``k`` on: dropped)."""
    scene = head_scene(ep, rig, "")
    hue = float(name.removeprefix("hue_"))  # the injector's name for it; the detector's class may differ by a few °
    colour = min(scene.classes, key=lambda c: min(abs(c.hue_deg - hue), 360 - abs(c.hue_deg - hue)))
    rgb = tuple(int(200 * x) for x in colour.rgb)
    cam = WristCamera.from_rig(rig, VIEW)
    poses = cam.poses(rig, ep.state)
    h, w = cam.height, cam.width
    frames = np.empty((ep.length, h, w, 3), np.uint8)
    frames[:] = TABLE
    v, u = np.mgrid[:h, :w]

    def disc(at: NDArray[np.float64]) -> NDArray[np.bool_]:
        return np.asarray((u - at[0]) ** 2 + (v - at[1]) ** 2 <= 7**2)

    anchor = np.array([BETWEEN if held else FAR], float)
    for t in range(k):
        at = anchor[0] if held else cam.reproject(anchor, poses[k - 1], poses[t], PLANE_Z)[0][0]
        frames[t, disc(at)] = rgb
    frames[k:, disc(anchor[0])] = paint
    if landed is not None:
        frames[k:, disc(np.array(landed, float))] = rgb
    frames[:, int(0.85 * h) :] = 20  # the gripper's body, in front of everything
    frames[:, int(0.65 * h) :, int(0.25 * w) : int(0.32 * w)] = 25  # its fingers
    frames[:, int(0.65 * h) :, int(0.68 * w) : int(0.75 * w)] = 25
    return frames


def _judge(
    ep: Episode,
    k: int,
    name: str,
    rig: RigConfig,
    *,
    held: bool,
    paint: tuple[int, int, int],
    grip: NDArray[np.float64],
    landed: tuple[int, int] | None = None,
) -> Finding | None:
    state = ep.state.copy()
    state[:, LEFT_GRIP] = grip
    ep = dataclasses.replace(ep, state=state)
    wrists = {VIEW: _wrist(ep, k, name, rig, held, paint, landed)}
    return check_wrist_objects(head_scene(ep, rig, ""), wrists, rig, ep.state, Thresholds())


def test_an_object_gone_from_an_open_grippers_view_is_found(deleted: tuple[Episode, int, str], rig: RigConfig) -> None:
    """An open gripper holds nothing: a blob resting on the table must show where the camera's motion takes it.
    That something brown now shows where it was in the image says nothing (that is where a held one would be)."""
    ep, k, name = deleted
    found = _judge(ep, k, name, rig, held=False, paint=TRAY, grip=np.ones(ep.length))
    assert found is not None and found.frame == k, found
    assert found.category == OBJECT_DISAPPEARED and VIEW in found.detail


def test_a_closed_gripper_may_hold_what_something_now_covers(deleted: tuple[Episode, int, str], rig: RigConfig) -> None:
    ep, k, name = deleted
    assert _judge(ep, k, name, rig, held=False, paint=TRAY, grip=np.full(ep.length, 0.3)) is None


def test_an_opening_gripper_excuses_only_what_lies_between_its_fingers(
    deleted: tuple[Episode, int, str], rig: RigConfig
) -> None:
    """What it held drops anywhere in view, or out of it (released objects fall out of a wrist view, behind the
    arm in the head view, within a frame: requiring them to land in view flagged 4 of 150 clean episodes on two
    varied sets); an object resting on the table it never held."""
    ep, k, name = deleted
    grip = np.where(np.arange(ep.length) < k, 0.3, 1.0)
    assert _judge(ep, k, name, rig, held=True, paint=TABLE, grip=grip, landed=FAR) is None
    assert _judge(ep, k, name, rig, held=True, paint=TABLE, grip=grip) is None
    found = _judge(ep, k, name, rig, held=False, paint=TABLE, grip=grip)
    assert found is not None and found.frame == k, found


def test_an_object_held_between_closed_fingers_can_only_stay_put(
    deleted: tuple[Episode, int, str], rig: RigConfig
) -> None:
    """Between closed fingers an object moves with the camera: gone from there, with the table showing, it
    vanished; with something else showing there, it may be behind it."""
    ep, k, name = deleted
    found = _judge(ep, k, name, rig, held=True, paint=TABLE, grip=np.full(ep.length, 0.3))
    assert found is not None and found.frame == k, found
    assert _judge(ep, k, name, rig, held=True, paint=TRAY, grip=np.full(ep.length, 0.3)) is None  # covered
