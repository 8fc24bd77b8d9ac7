"""Γ: markers on the projected pixels, size growing with opening, traces, determinism, edge cases."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from calib.camera_model import CameraModel
from pilworld.config.rig import RigConfig
from pilworld.control_video import ControlVideo, ControlVideoStyle
from pilworld.control_video.examples import HOME_Q14, random_chunks, reach_and_grasp_chunk
from pilworld.control_video.gamma import clip_segments
from pilworld.kinematics import DualArmKinematics
from pilworld.types import ActionChunk, ChunkSpec

SIM = Path(__file__).resolve().parents[3] / "configs" / "rig" / "sim_dual_ur5e.yaml"
CHANNEL = (0, 2)  # the dominant colour channel of each arm's marker: left red, right blue


@pytest.fixture(scope="module")
def rig() -> RigConfig:
    return RigConfig.load(SIM)


def _expected_uv(rig: RigConfig, chunk: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Projected TCPs of the stride-aligned actions, computed without Γ: FK, then the camera model."""
    sa = chunk[2:45:3]
    pts = rig.kinematics.gripper_points(sa)
    uv, visible = rig.head_camera_model.project(pts.reshape(-1, 3))
    return uv.reshape(15, 2, 2), visible.reshape(15, 2)


def _centroid(img: np.ndarray, channel: int, around: np.ndarray, radius: float) -> np.ndarray:
    h, w = img.shape[:2]
    ys, xs = np.mgrid[0:h, 0:w]
    window = (xs - around[0]) ** 2 + (ys - around[1]) ** 2 <= (radius + 2.5) ** 2
    weight = img[..., channel].astype(np.float64) * window
    return np.array([(weight * xs).sum(), (weight * ys).sum()]) / weight.sum()


def _fully_inside(uv: np.ndarray, r: float, w: int, h: int) -> bool:
    return bool(r + 1 < uv[0] < w - 2 - r and r + 1 < uv[1] < h - 2 - r)


def test_marker_centres_on_projected_pixels(rig: RigConfig) -> None:
    gamma = ControlVideo.from_rig(rig, style=ControlVideoStyle(trace_length=0))
    chunk = reach_and_grasp_chunk()
    frames = gamma(chunk)
    assert frames.shape == (15, 128, 128, 3) and frames.dtype == np.uint8
    uv, visible = _expected_uv(rig, chunk)
    radius = gamma.style.marker_radius(chunk[2:45:3][:, [6, 13]], 128, 128)
    errors = []
    for k in range(15):
        for arm in (0, 1):
            assert visible[k, arm], "the example chunk keeps both grippers in view"
            if _fully_inside(uv[k, arm], radius[k, arm], 128, 128):
                c = _centroid(frames[k], CHANNEL[arm], uv[k, arm], radius[k, arm])
                errors.append(np.linalg.norm(c - uv[k, arm]))
    assert len(errors) == 30
    assert max(errors) < 0.5, f"max marker centre error {max(errors):.3f} px"
    # The motion is real: the left marker travels several pixels over the chunk.
    assert np.linalg.norm(uv[-1, 0] - uv[0, 0]) > 5


def test_marker_centres_with_traces_and_random_chunks(rig: RigConfig) -> None:
    gamma = ControlVideo.from_rig(rig)
    chunks = random_chunks(8, seed=1)
    frames = gamma.render_batch(chunks)
    checked = 0
    for b in range(8):
        uv, visible = _expected_uv(rig, chunks[b].astype(np.float64))
        radius = gamma.style.marker_radius(chunks[b, 2:45:3][:, [6, 13]], 128, 128)
        for k in range(15):
            for arm in (0, 1):
                if not (visible[k, arm] and _fully_inside(uv[k, arm], radius[k, arm], 128, 128)):
                    continue
                # Traces are drawn at ≤ 75 % brightness, so the full-brightness core is the marker alone.
                core = np.where(frames[b, k, ..., CHANNEL[arm]] >= 250, 255, 0).astype(np.uint8)
                img = np.zeros_like(frames[b, k])
                img[..., CHANNEL[arm]] = core
                c = _centroid(img, CHANNEL[arm], uv[k, arm], radius[k, arm])
                assert np.linalg.norm(c - uv[k, arm]) < 0.5
                checked += 1
    assert checked > 150


def test_marker_radius_strictly_increases_with_opening(rig: RigConfig) -> None:
    style = ControlVideoStyle(trace_length=0)
    grips = np.linspace(0.0, 1.0, 21)
    r = style.marker_radius(grips, 128, 128)
    assert np.all(np.diff(r) > 0)
    assert r[0] == pytest.approx(0.025 * 128) and r[-1] == pytest.approx(0.07 * 128)
    assert style.marker_radius(1.7, 128, 128) == style.marker_radius(1.0, 128, 128)  # clipped

    gamma = ControlVideo.from_rig(rig, style=style)
    chunks = np.repeat(HOME_Q14[None, None].astype(np.float64), 21, axis=0).repeat(50, axis=1)
    chunks[:, :, 6] = grips[:, None]
    frames = gamma.render_batch(chunks)
    uv, _ = _expected_uv(rig, chunks[0])
    ys, xs = np.mgrid[0:128, 0:128]
    window = (xs - uv[0, 0, 0]) ** 2 + (ys - uv[0, 0, 1]) ** 2 <= 12**2  # the left marker only
    area = (frames[:, 0, ..., 0] * window).astype(np.float64).sum(axis=(1, 2)) / 255.0  # red channel
    assert np.all(np.diff(area) > 0), area
    measured = np.sqrt(area / np.pi)
    np.testing.assert_allclose(measured, r, atol=0.2)


def test_two_renders_are_byte_identical(rig: RigConfig) -> None:
    chunk = random_chunks(1, seed=7)[0]
    a = ControlVideo.from_rig(rig)(chunk, previous_state=HOME_Q14)
    b = ControlVideo.from_rig(RigConfig.load(SIM))(ActionChunk.from_array(chunk), previous_state=HOME_Q14)
    assert a.tobytes() == b.tobytes()
    batch = ControlVideo.from_rig(rig).render_batch(np.stack([chunk, chunk]), np.stack([HOME_Q14, HOME_Q14]))
    assert batch[0].tobytes() == a.tobytes() and batch[1].tobytes() == a.tobytes()


def test_traces_fade_and_previous_state_adds_first_segment(rig: RigConfig) -> None:
    gamma = ControlVideo.from_rig(rig)
    chunk = reach_and_grasp_chunk()
    start = chunk[0].copy()
    start[:6] += 0.15  # the left arm starts elsewhere, so a segment leads into frame 0
    plain = gamma(chunk)
    with_prev = gamma(chunk, previous_state=start)
    assert not np.array_equal(plain[0], with_prev[0])
    np.testing.assert_array_equal(plain[4:], with_prev[4:])  # beyond trace_length the start is forgotten

    uv, _ = _expected_uv(rig, chunk.astype(np.float64))
    radius = gamma.style.marker_radius(chunk[2:45:3][:, [6, 13]], 128, 128)
    h, w = 128, 128
    ys, xs = np.mgrid[0:h, 0:w]
    for k in range(1, 15):
        outside = (xs - uv[k, 0, 0]) ** 2 + (ys - uv[k, 0, 1]) ** 2 > (radius[k, 0] + 1.5) ** 2
        trace = plain[k, ..., 0] * outside
        if np.linalg.norm(uv[k, 0] - uv[k - 1, 0]) > radius[k, 0] + 3:
            assert trace.max() > 0, f"frame {k}: no trace behind a moving marker"
        assert trace.max() <= round(0.75 * 255) + 1, "traces are dimmer than markers"
    none = ControlVideo.from_rig(rig, style=ControlVideoStyle(trace_length=0))(chunk)
    assert none[..., 0].sum() < plain[..., 0].sum()


def test_points_behind_and_off_image_never_crash(rig: RigConfig) -> None:
    # A camera between the arms looking along +y: the left gripper is in front, the right one behind.
    cam = CameraModel.look_at(
        eye=np.array([0.1, 0.0, 0.1]),
        target=np.array([0.1, 1.0, 0.1]),
        up=np.array([0.0, 0.0, 1.0]),
        fovy_deg=90.0,
        width=96,
        height=64,
    )
    gamma = ControlVideo(rig.kinematics, cam)
    chunk = random_chunks(1, seed=3)[0]
    frames = gamma(chunk, previous_state=HOME_Q14)
    assert frames.shape == (15, 64, 96, 3)
    geo = gamma.geometry(gamma.stride_aligned(chunk[None]))
    assert not geo.usable[0, :, 1].any() and not geo.marker[0, :, 1].any()  # right gripper behind
    assert frames[..., 2].max() == 0 and frames[..., 0].max() == 255  # no blue at all: right arm unseen

    # Narrow camera on the left gripper: a sweep that leaves the image is clipped, not wrapped.
    narrow = CameraModel.look_at(
        eye=np.array([0.1, 0.27, 0.6]),
        target=np.array([0.1, 0.27, 0.1]),
        up=np.array([1.0, 0.0, 0.0]),
        fovy_deg=10.0,
        width=64,
        height=64,
    )
    sweep = np.repeat(HOME_Q14[None].astype(np.float64), 50, axis=0)
    sweep[:, 0] += np.linspace(0.0, 0.6, 50)  # pan the left arm far out of the narrow view
    g2 = ControlVideo(rig.kinematics, narrow)
    out = g2(sweep)
    geo2 = g2.geometry(g2.stride_aligned(sweep[None]))
    assert geo2.visible[0, 0, 0] and not geo2.visible[0, -1, 0]
    assert out[0, ..., 0].max() == 255 and out[-1].max() == 0  # first frame marker; last frame empty
    assert np.all(np.isfinite(geo2.seg_a)) and np.all(np.isfinite(geo2.seg_b))


def test_clip_segments() -> None:
    a = np.array([[-10.0, 5.0], [2.0, 2.0], [20.0, 20.0], [5.0, -3.0]])
    b = np.array([[20.0, 5.0], [8.0, 8.0], [30.0, 30.0], [5.0, -1.0]])
    ca, cb, ok = clip_segments(a, b, (0.0, 0.0), (10.0, 10.0))
    assert ok.tolist() == [True, True, False, False]
    np.testing.assert_allclose(ca[0], [0.0, 5.0])
    np.testing.assert_allclose(cb[0], [10.0, 5.0])
    np.testing.assert_allclose(ca[1], a[1])
    np.testing.assert_allclose(cb[1], b[1])


def test_image_size_and_chunk_spec_are_configurable(rig: RigConfig) -> None:
    big = RigConfig.model_validate({**rig.model_dump(), "image_size": {"width": 224, "height": 160}})
    gamma = ControlVideo.from_rig(big, spec=ChunkSpec(horizon=50, frames=10, stride=5))
    out = gamma(reach_and_grasp_chunk())
    assert out.shape == (10, 160, 224, 3)


@pytest.mark.parametrize(
    ("chunk", "message"),
    [
        (np.zeros((50, 13)), r"expected an action chunk \(H, 14\)"),
        (np.zeros((44, 14)), "chunk has 44 steps but K·Δ"),
        (np.full((50, 14), np.nan), "non-finite"),
    ],
)
def test_bad_chunks_raise(rig: RigConfig, chunk: np.ndarray, message: str) -> None:
    with pytest.raises(ValueError, match=message):
        ControlVideo.from_rig(rig)(chunk)


def test_bad_style_raises() -> None:
    with pytest.raises(ValueError, match="strictly with opening"):
        ControlVideoStyle(radius_closed=0.1, radius_open=0.05)
    with pytest.raises(ValueError, match="distinct colours"):
        ControlVideoStyle(left_color=(1, 2, 3), right_color=(1, 2, 3))


def test_overlapping_markers_keep_their_own_channel(rig: RigConfig) -> None:
    # Both arms on the same mount with the same joints: the two markers coincide exactly.
    kin = DualArmKinematics(left=rig.kinematics.left, right=rig.kinematics.left)
    gamma = ControlVideo(kin, rig.head_camera_model, style=ControlVideoStyle(trace_length=0))
    chunk = np.repeat(HOME_Q14[None].astype(np.float64), 50, axis=0)
    chunk[:, 7:13] = chunk[:, 0:6]
    chunk[:, 6], chunk[:, 13] = 1.0, 0.0  # left open (large), right closed (small), right drawn second
    frame = gamma(chunk)[0]
    uv, _ = _expected_uv(rig, chunk)
    r = gamma.style.marker_radius(np.array([1.0, 0.0]), 128, 128)
    for arm, channel in ((0, 0), (1, 2)):
        area = frame[..., channel].astype(np.float64).sum() / 255.0
        assert area == pytest.approx(np.pi * r[arm] ** 2, rel=0.08), "a marker was hidden by the other arm"
        c = _centroid(frame, channel, uv[0, 0], r[arm])
        assert np.linalg.norm(c - uv[0, 0]) < 0.5
