"""A wrist view that jumps ahead of its camera (hallucination_ego): found at its frame over a textured table,
and not flagged where the camera's own motion, a frame of lag, a moving shadow or a uniform table explain it.

The wrist frames are rendered here from a textured table plane, seen from each camera pose the state's
kinematics give (the same poses the check reads), with the own gripper drawn dark at the image's foot.
"""

from __future__ import annotations

import cv2
import numpy as np
import pytest
from numpy.typing import NDArray

from pilworld.config.rig import RigConfig
from pilworld.data.episode import Episode
from pilworld.judges.hallucination_checks import ARM_MOTION, Thresholds
from pilworld.judges.hallucination_ego import check_wrist_motion, plane_homography
from pilworld.judges.hallucination_wrist import WristCamera
from tests.pilworld.judges.hallucination_data import clean_episodes, sim_rig

VIEWS = ("cam_left_wrist", "cam_right_wrist")
JUMP = 5  # frames a faulted view runs ahead
EXTENT = 1.0  # the texture covers x, y in [-EXTENT, EXTENT] m of the rig frame


@pytest.fixture(scope="module")
def rig() -> RigConfig:
    return sim_rig()


@pytest.fixture(scope="module")
def episode(tmp_path_factory: pytest.TempPathFactory) -> Episode:
    return clean_episodes(tmp_path_factory.getbasetemp())[0]  # both arms move over the table


def _texture(seed: int, contrast: float) -> NDArray[np.float32]:
    """A speckled laminate: grey with blurred random grain, ``contrast`` levels peak to peak (about)."""
    rng = np.random.default_rng(seed)
    grain = cv2.GaussianBlur(rng.standard_normal((1024, 1024)).astype(np.float32), (0, 0), 2.0)
    return (140 + contrast * grain / (4 * grain.std())).astype(np.float32)


def _render(cam: WristCamera, poses: NDArray[np.float64], texture: NDArray[np.float32]) -> NDArray[np.uint8]:
    """(T, H, W, 3): the plane z = 0 painted with ``texture``, seen from ``poses``, the gripper dark at the foot."""
    v, u = np.mgrid[: cam.height, : cam.width].astype(np.float64)
    rays = np.stack([u, v, np.ones_like(u)], -1) @ np.linalg.inv(cam.K).T
    n = texture.shape[0]
    out = np.empty((len(poses), cam.height, cam.width, 3), np.uint8)
    for t, T in enumerate(poses):
        d = rays @ T[:3, :3].T
        s = -T[2, 3] / d[..., 2]
        xy = T[:2, 3] + s[..., None] * d[..., :2]
        px = ((xy + EXTENT) / (2 * EXTENT) * (n - 1)).astype(np.float32)
        grey = cv2.remap(texture, px[..., 0], px[..., 1], cv2.INTER_LINEAR, borderMode=cv2.BORDER_REFLECT)
        frame = np.clip(grey, 0, 255).astype(np.uint8)
        frame[int(0.85 * cam.height) :] = 20  # the gripper's body
        frame[int(0.7 * cam.height) :, int(0.25 * cam.width) : int(0.32 * cam.width)] = 25  # its fingers
        frame[int(0.7 * cam.height) :, int(0.68 * cam.width) : int(0.75 * cam.width)] = 25
        out[t] = np.repeat(frame[..., None], 3, axis=2)
    return out


def _wrists(
    rig: RigConfig, state: NDArray[np.float32], texture: NDArray[np.float32], shown: NDArray[np.int64] | None = None
) -> dict[str, NDArray[np.uint8]]:
    """Each wrist view rendered from the pose of frame ``shown[t]`` (default: its own frame)."""
    out = {}
    for name in VIEWS:
        cam = WristCamera.from_rig(rig, name)
        poses = cam.poses(rig, state)
        out[name] = _render(cam, poses if shown is None else poses[shown], texture)
    return out


def _moving_frame(rig: RigConfig, state: NDArray[np.float32], name: str, after: int) -> int:
    """The first frame ``k`` after ``after`` where a jump of :data:`JUMP` frames moves the camera ``name``'s view
    of the table by 15–40 px: a clear jump whose view still overlaps the frame before."""
    cam = WristCamera.from_rig(rig, name)
    poses = cam.poses(rig, state)
    centre = np.array([[(cam.width - 1) / 2, (cam.height - 1) / 2]])
    for k in range(after, len(state) - JUMP):
        uv, ok = cam.reproject(centre, poses[k - 1], poses[k + JUMP], 0.0)
        if ok.all() and 15 <= float(np.hypot(*(uv[0] - centre[0]))) <= 40:
            return k
    raise AssertionError(f"{name} never moves in this episode")


def _jumped(rig: RigConfig, episode: Episode, texture: NDArray[np.float32]) -> tuple[int, dict[str, NDArray[np.uint8]]]:
    """(k, the wrist views) with every view :data:`JUMP` frames ahead of the state from ``k`` on."""
    k = _moving_frame(rig, episode.state, VIEWS[1], 10)
    shown = np.arange(episode.length)
    shown[k:] = np.minimum(shown[k:] + JUMP, episode.length - 1)
    return k, _wrists(rig, episode.state, texture, shown=shown)


def test_the_plane_homography_carries_table_points_between_poses(rig: RigConfig, episode: Episode) -> None:
    cam = WristCamera.from_rig(rig, VIEWS[0])
    poses = cam.poses(rig, episode.state)
    a, b = poses[20], poses[30]
    uv = np.array([[10.0, 15.0], [100.0, 40.0], [64.0, 90.0]])
    H = plane_homography(cam, b, a)
    assert H is not None
    mapped = cv2.perspectiveTransform(uv[None], H)[0]
    expected, ok = cam.reproject(uv, a, b, 0.0)
    assert ok.all()
    np.testing.assert_allclose(mapped, expected, atol=1e-3)


def test_a_textured_table_seen_as_the_camera_moves_is_not_flagged(rig: RigConfig, episode: Episode) -> None:
    wrists = _wrists(rig, episode.state, _texture(0, 40))
    assert check_wrist_motion(wrists, rig, episode.state, Thresholds()) is None


def test_a_view_that_lags_its_state_by_a_frame_is_not_flagged(rig: RigConfig, episode: Episode) -> None:
    """The imagined branch's state is the command, which the rendered arm reaches a frame later."""
    T = episode.length
    lag = np.maximum(np.arange(T) - 1, 0)
    wrists = _wrists(rig, episode.state, _texture(1, 40), shown=lag)
    assert check_wrist_motion(wrists, rig, episode.state, Thresholds()) is None


def test_a_view_that_jumps_ahead_is_found_at_its_frame(rig: RigConfig, episode: Episode) -> None:
    k, wrists = _jumped(rig, episode, _texture(2, 40))
    found = check_wrist_motion(wrists, rig, episode.state, Thresholds())
    assert found is not None and found.frame == k, found
    assert found.category == ARM_MOTION and "jumped ahead" in found.detail


def test_a_shadow_sweeping_over_the_table_is_not_a_jump(rig: RigConfig, episode: Episode) -> None:
    """A dark patch crossing the view spoils every candidate alike: no later pose explains the frame better."""
    wrists = _wrists(rig, episode.state, _texture(3, 40))
    for frames in wrists.values():
        for t in range(len(frames)):
            x = (7 * t) % 100
            frames[t, 10:60, x : x + 40] = (frames[t, 10:60, x : x + 40] * 0.45).astype(np.uint8)
    assert check_wrist_motion(wrists, rig, episode.state, Thresholds()) is None


def test_a_uniform_table_shows_no_jump_and_none_is_claimed(rig: RigConfig, episode: Episode) -> None:
    """Without texture nothing tells the poses apart: the check stays silent (the head view's arm check is the
    one that sees a jump there)."""
    _, wrists = _jumped(rig, episode, _texture(4, 0.0))
    assert check_wrist_motion(wrists, rig, episode.state, Thresholds()) is None


def test_views_the_rig_does_not_know_or_of_another_size_are_left_alone(rig: RigConfig, episode: Episode) -> None:
    _, wrists = _jumped(rig, episode, _texture(5, 40))
    renamed = {"cam_other": wrists[VIEWS[1]]}
    assert check_wrist_motion(renamed, rig, episode.state, Thresholds()) is None
    small = {VIEWS[1]: wrists[VIEWS[1]][:, ::2, ::2].copy()}
    assert check_wrist_motion(small, rig, episode.state, Thresholds()) is None
