"""Where a gripper let go, from the state and the rig alone."""

from __future__ import annotations

import numpy as np
import pytest

from pilworld.config.rig import RigConfig
from pilworld.judges.learned.release import crop, last_release, releases
from pilworld.types import LEFT_GRIP, RIGHT_GRIP
from simrig.files import SIM_RIG
from simrig.poses import HOME_Q14


@pytest.fixture(scope="module")
def rig() -> RigConfig:
    return RigConfig.load(SIM_RIG)


def _state(left: list[float], right: list[float]) -> np.ndarray:
    state = np.repeat(HOME_Q14[None], len(left), axis=0).astype(np.float32)
    state[:, LEFT_GRIP], state[:, RIGHT_GRIP] = left, right
    state[:, 0] += np.linspace(0, 0.3, len(left))  # the left arm moves, so each frame's tool point differs
    return state


def test_openings_from_closed_are_releases_and_the_last_one_is_projected(rig: RigConfig) -> None:
    # left: open, closes (grasp), opens over frames 5–7; right: closes at 6 and opens at 9
    left = [1, 1, 0.2, 0.2, 0.2, 0.4, 0.7, 1, 1, 1, 1]
    right = [1, 1, 1, 1, 1, 1, 0.1, 0.1, 0.1, 0.5, 1]
    state = _state(left, right)
    assert releases(state) == [(5, 0), (9, 1)]
    r = last_release(state, rig)
    assert r is not None and (r.frame, r.arm) == (9, 1)
    uv, visible = rig.head_camera_model.project(rig.kinematics.gripper_points(state[9].astype(np.float64))[1])
    assert r.uv == pytest.approx((float(uv[0]), float(uv[1]))) and r.visible == bool(visible)


def test_no_release_without_a_closed_gripper_opening(rig: RigConfig) -> None:
    assert last_release(_state([1.0] * 6, [1, 0.9, 0.95, 1, 1, 1]), rig) is None  # never closed: no release
    assert releases(_state([1, 0.1, 0.1, 0.1, 0.1, 0.1], [1.0] * 6)) == []  # closed to the end: still held


def test_crop_is_centred_and_repeats_the_border() -> None:
    image = np.zeros((20, 30, 3), np.uint8)
    image[10, 15] = 255
    c = crop(image, (15.2, 9.8), 8)
    assert c.shape == (8, 8, 3) and c[4, 4, 0] == 255
    corner = crop(image, (-5.0, 100.0), 8)  # outside: clamped to the image's corner
    assert corner.shape == (8, 8, 3)
