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
    state[:, 0] -= np.linspace(0.4, 0.8, len(left))  # the left arm pans into the head view, a new tool point each frame
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


def test_a_release_crop_judge_reads_the_head_view_where_the_gripper_let_go(rig: RigConfig) -> None:
    from pilworld.data.episode import Episode
    from pilworld.judges.learned.examples import episode_example
    from pilworld.judges.learned.inputs import InputSpec, JudgeInputError

    state = _state([1, 0.2, 0.2, 0.2, 0.6, 1, 1, 1], [1.0] * 8)
    r = last_release(state, rig)
    assert r is not None and r.visible
    head = np.zeros((8, 128, 128, 3), np.uint8)
    u, v = round(r.uv[0]), round(r.uv[1])
    head[:, v - 1 : v + 2, u - 1 : u + 2] = 255  # something bright where the gripper let go
    images = {"cam_high": head, "cam_left_wrist": np.zeros_like(head)}
    episode = Episode(images=images, state=state, action=state.copy(), task="put it there.")
    spec = InputSpec.from_views({"cam_high": (128, 128), "cam_left_wrist": (128, 128)}, 14, side=32, release_crop=16)
    example = episode_example(episode, spec, rig)
    assert example.frames.shape == (3, 3, 6, 32, 32)  # 3 last frames, 2 views + the crop, first|last
    crop_last = example.frames[0, 2, 3:].astype(float)  # the crop of the last frame (16 px → 32: 2× magnified)
    assert crop_last[:, 14:18, 14:18].mean() > 200 and crop_last[:, :8, :8].max() == 0
    with pytest.raises(JudgeInputError, match="needs the rig"):
        episode_example(episode, spec, None)
    with pytest.raises(ValueError, match="head view"):
        InputSpec.from_views({"cam_left_wrist": (128, 128)}, 14, release_crop=16)
