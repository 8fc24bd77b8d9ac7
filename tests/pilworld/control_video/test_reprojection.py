"""The scene reprojection prior: exact plane geometry, masks, head fallback, input errors, one sim check."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from numpy.typing import NDArray

from calib.camera_model import CameraModel
from pilworld.config.rig import RigConfig
from pilworld.control_video.cameras import RigCameras
from pilworld.control_video.reprojection import (
    SOURCE_HEAD,
    SOURCE_NONE,
    SOURCE_OWN,
    SceneReprojector,
    plane_homography,
    warp_through_plane,
)
from simrig.poses import HOME_Q14

RIG = Path(__file__).resolve().parents[3] / "configs" / "rig" / "sim_dual_ur5e.yaml"
SIZE = 64
WRISTS = ("cam_left_wrist", "cam_right_wrist")


def texture(points: NDArray[np.float64]) -> NDArray[np.float64]:
    """A smooth colour pattern on the plane (periods 12–30 cm, so a 64 px camera resolves it)."""
    x, y = points[..., 0], points[..., 1]
    return np.stack(
        [
            128 + 90 * np.sin(2 * np.pi * x / 0.3),
            128 + 90 * np.cos(2 * np.pi * y / 0.25),
            128 + 60 * np.sin(2 * np.pi * (x + y) / 0.12),
        ],
        axis=-1,
    )


def render_plane(model: CameraModel, plane_z: float = 0.0) -> tuple[NDArray[np.uint8], NDArray[np.bool_]]:
    """The textured plane seen by ``model`` (posed), computed per pixel by the camera model itself."""
    v, u = np.mgrid[0 : model.height, 0 : model.width].astype(np.float64)
    points, ok = model.backproject_to_plane(np.stack([u, v], axis=-1), plane_z)
    image = np.where(ok[..., None], texture(np.nan_to_num(points)), 0.0)
    return np.clip(np.rint(image), 0, 255).astype(np.uint8), ok


def camera(eye: tuple[float, float, float], target: tuple[float, float, float], **kw: object) -> CameraModel:
    cam = CameraModel.look_at(eye, target, up=(1.0, 0.0, 0.0), fovy_deg=60.0, width=SIZE, height=SIZE)
    return cam if not kw else CameraModel(cam.K, kw["dist"], cam.T_cam_base, SIZE, SIZE)  # type: ignore[arg-type]


@pytest.fixture(scope="module")
def cameras() -> RigCameras:
    rig = RigConfig.load(RIG)
    rig = RigConfig.model_validate({**rig.model_dump(), "image_size": {"width": SIZE, "height": SIZE}})
    return RigCameras.from_rig(rig)


def moved(q: NDArray[np.float64], k: int = 4, scale: float = 0.08) -> NDArray[np.float64]:
    """K joint vectors drifting from ``q`` (all joints of both arms; the wrist cameras move)."""
    direction = np.tile([1.0, -0.6, 0.8, 0.5, -0.7, 0.9, 0.0], 2)
    out: NDArray[np.float64] = q[None] + scale * np.linspace(0.25, 1.0, k)[:, None] * direction[None]
    return out


def scene_images(cameras: RigCameras, q: NDArray[np.float64]) -> dict[str, NDArray[np.uint8]]:
    models = cameras.models_at(q)
    return {v: render_plane(models[v])[0] for v in cameras.names}


# ---------------------------------------------------------------------- plane geometry


def test_homography_maps_plane_points_to_their_pixels() -> None:
    cam = camera((0.0, 0.1, 0.8), (0.2, 0.0, 0.0))
    pts = np.array([[0.1, 0.05, 0.02], [0.3, -0.1, 0.02], [0.0, 0.2, 0.02]])
    uv, _ = cam.project(pts)
    h = plane_homography(cam.K, cam.T_cam_base, 0.02) @ np.c_[pts[:, :2], np.ones(3)].T
    np.testing.assert_allclose((h[:2] / h[2]).T, uv, atol=1e-9)


@pytest.mark.parametrize("method", ["homography", "remap"])
def test_textured_plane_warps_onto_the_other_camera(method: str) -> None:
    src = camera((0.0, 0.0, 0.7), (0.15, 0.0, 0.0))
    dst = camera((0.12, 0.1, 0.55), (0.2, -0.05, 0.0))
    src_img, _ = render_plane(src)
    true, _ = render_plane(dst)
    warped, ok = warp_through_plane(src_img, None, src, dst, dst.T_cam_base[None], method=method)
    assert warped.shape == (1, SIZE, SIZE, 3) and ok.shape == (1, SIZE, SIZE)
    assert ok.mean() > 0.5
    err = np.abs(warped[0].astype(int) - true.astype(int))[ok[0]]
    assert err.mean() < 2.0 and np.percentile(err, 99) < 12
    assert (warped[0][~ok[0]] == 0).all()


def test_distorted_cameras_go_through_the_remap() -> None:
    dist = np.array([-0.25, 0.08, 0.001, -0.002, 0.0])
    src = camera((0.0, 0.0, 0.7), (0.15, 0.0, 0.0), dist=dist)
    dst = camera((0.1, -0.08, 0.6), (0.2, 0.05, 0.0), dist=dist)
    warped, ok = warp_through_plane(render_plane(src)[0], None, src, dst, dst.T_cam_base[None])
    true, _ = render_plane(dst)
    err = np.abs(warped[0].astype(int) - true.astype(int))[ok[0]]
    assert ok.mean() > 0.5 and err.mean() < 2.0
    # Ignoring the distortion (a plain homography between the pinhole parts) is measurably worse.
    with pytest.raises(ValueError, match="method"):
        warp_through_plane(render_plane(src)[0], None, src, dst, dst.T_cam_base[None], method="homography")
    src0, dst0 = camera((0.0, 0.0, 0.7), (0.15, 0.0, 0.0)), camera((0.1, -0.08, 0.6), (0.2, 0.05, 0.0))
    wrong, ok0 = warp_through_plane(render_plane(src)[0], None, src0, dst0, dst0.T_cam_base[None])
    both = ok[0] & ok0[0]
    assert np.abs(wrong[0].astype(int) - true.astype(int))[both].mean() > 2 * err.mean()


def test_plane_behind_a_camera_is_invalid() -> None:
    src = camera((0.0, 0.0, 0.7), (0.15, 0.0, 0.0))
    up = CameraModel.look_at((0.0, 0.0, 0.5), (0.3, 0.0, 1.0), up=(0.0, 0.0, 1.0), fovy_deg=60, width=SIZE, height=SIZE)
    _, ok = warp_through_plane(render_plane(src)[0], None, src, up, up.T_cam_base[None])
    assert not ok.any()  # looking up: every ray leaves the plane behind (a homography alone would mirror it)


# ---------------------------------------------------------------------- the rig's prior


def test_identity_pose_gives_the_current_frame(cameras: RigCameras) -> None:
    images = scene_images(cameras, HOME_Q14)
    prior = SceneReprojector(cameras)(images, HOME_Q14, np.stack([HOME_Q14] * 3))
    for v in cameras.names:
        assert prior.images[v].shape == (3, SIZE, SIZE, 3)
        assert (prior.source[v] == SOURCE_OWN).all(), v
        assert (prior.images[v] == images[v][None]).all(), v


def test_prior_matches_the_future_render_own_and_head(cameras: RigCameras) -> None:
    future = moved(HOME_Q14)
    images = scene_images(cameras, HOME_Q14)
    prior = SceneReprojector(cameras)(images, HOME_Q14, future)
    for v in WRISTS:
        true = np.stack([render_plane(cameras.models_at(q)[v])[0] for q in future])
        src = prior.source[v]
        err = np.abs(prior.images[v].astype(int) - true.astype(int))
        assert (src == SOURCE_OWN).mean() > 0.3 and (src == SOURCE_HEAD).any(), v
        assert err[src == SOURCE_OWN].mean() < 2.5, v
        assert err[src == SOURCE_HEAD].mean() < 6.0, v  # the head view sees the plane ~4x coarser


def test_fallback_fills_exactly_what_the_wrist_lacks(cameras: RigCameras) -> None:
    future = moved(HOME_Q14, k=3, scale=0.12)
    red = np.zeros((SIZE, SIZE, 3), np.uint8)
    red[..., 0] = 200
    green = np.zeros_like(red)
    green[..., 1] = 200
    images = {v: (green if v == "cam_high" else red) for v in cameras.names}
    prior = SceneReprojector(cameras, match_head_colour=False)(images, HOME_Q14, future)
    now = cameras.models_at(HOME_Q14)
    v, u = np.mgrid[0:SIZE, 0:SIZE].astype(np.float64)
    for view in WRISTS:
        src, img = prior.source[view], prior.images[view]
        assert (img[src == SOURCE_OWN] == [200, 0, 0]).all() and (img[src == SOURCE_HEAD] == [0, 200, 0]).all()
        assert (img[src == SOURCE_NONE] == 0).all()
        for k, q in enumerate(future):
            # Independently: back-project each future pixel onto the plane, project into the current cameras.
            points, hit = cameras.models_at(q)[view].backproject_to_plane(np.stack([u, v], -1))
            own, head = src[k] == SOURCE_OWN, src[k] == SOURCE_HEAD
            own_lo, own_hi = lands_inside(now[view], points, hit)
            head_lo, head_hi = lands_inside(now["cam_high"], points, hit)
            assert (own <= own_hi).all() and (own_lo <= own).all(), (view, k)
            assert (head <= head_hi & ~own).all() and (head_lo & ~own <= head).all(), (view, k)
            assert head.sum() > 50 and (~own_hi & hit).sum() > 50  # the case is exercised


def lands_inside(
    model: CameraModel, points: NDArray[np.float64], hit: NDArray[np.bool_]
) -> tuple[NDArray[np.bool_], NDArray[np.bool_]]:
    """Pixels whose plane point projects a pixel inside ``model``'s image (lower) or within its edge (upper)."""
    uv, vis = model.project(np.nan_to_num(points))
    n = model.width

    def inside(margin: float) -> NDArray[np.bool_]:
        return hit & vis & (uv >= -0.5 + margin).all(-1) & (uv <= n - 0.5 - margin).all(-1)

    return inside(1.01), inside(0.0)


def test_head_colours_are_matched_to_the_wrist_camera(cameras: RigCameras) -> None:
    future = moved(HOME_Q14)
    images = scene_images(cameras, HOME_Q14)
    images["cam_high"] = (images["cam_high"] * np.array([0.7, 0.85, 1.0])).astype(np.uint8)  # another exposure
    errors = {}
    for match in (False, True):
        prior = SceneReprojector(cameras, match_head_colour=match)(images, HOME_Q14, future)
        v = "cam_left_wrist"
        true = np.stack([render_plane(cameras.models_at(q)[v])[0] for q in future])
        head = prior.source[v] == SOURCE_HEAD
        errors[match] = np.abs(prior.images[v].astype(int) - true)[head].mean()
    assert errors[True] < 4.0 and errors[False] > 3 * errors[True], errors


def test_robot_masks_are_respected(cameras: RigCameras) -> None:
    images = scene_images(cameras, HOME_Q14)
    now_masks = {v: np.zeros((SIZE, SIZE), bool) for v in cameras.names}
    future_masks = {v: np.zeros((2, SIZE, SIZE), bool) for v in cameras.names}
    for v in cameras.names:
        now_masks[v][40:, 20:44] = True  # "the gripper" in the current frame
        future_masks[v][1, :10, :] = True  # where the arm will be in frame 2
    prior = SceneReprojector(cameras)(images, HOME_Q14, np.stack([HOME_Q14] * 2), now_masks, future_masks)
    for v in cameras.names:
        src = prior.source[v]
        assert (src[:, 40:, 20:44] != SOURCE_OWN).all(), v  # never sampled from robot pixels
        assert (src[1, :10] == SOURCE_NONE).all() and (prior.images[v][1, :10] == 0).all(), v
        assert (src[0, :10] == SOURCE_OWN).all(), v
    assert (prior.source["cam_high"][:, 40:, 20:44] == SOURCE_NONE).all()  # a static view has no fallback
    valid = prior.valid["cam_left_wrist"]
    assert valid.dtype == bool and valid[0, 0, 0] and not valid[1, 0, 0]


def test_bad_inputs_name_the_field(cameras: RigCameras) -> None:
    rep = SceneReprojector(cameras)
    images = scene_images(cameras, HOME_Q14)
    future = np.stack([HOME_Q14] * 2)
    with pytest.raises(ValueError, match=r"current_images: missing view.*cam_left_wrist"):
        rep({k: i for k, i in images.items() if k != "cam_left_wrist"}, HOME_Q14, future)
    with pytest.raises(ValueError, match=r"current_images\['cam_high'\]: expected uint8 \(64, 64, 3\)"):
        rep({**images, "cam_high": images["cam_high"][:32]}, HOME_Q14, future)
    with pytest.raises(ValueError, match="current_q14: joint values must be finite"):
        rep(images, np.where(np.arange(14) == 3, np.nan, HOME_Q14), future)
    with pytest.raises(ValueError, match=r"future_q14: expected shape \(K, 14\)"):
        rep(images, HOME_Q14, HOME_Q14)
    with pytest.raises(ValueError, match="future_q14: joint values must be finite"):
        rep(images, HOME_Q14, np.full((2, 14), np.inf))
    masks = {v: np.zeros((SIZE, SIZE), bool) for v in cameras.names}
    with pytest.raises(ValueError, match=r"future_robot_masks\['cam_high'\]: expected bool \(2, 64, 64\)"):
        rep(images, HOME_Q14, future, masks, masks)
    with pytest.raises(ValueError, match=r"current_robot_masks\['cam_high'\]: expected bool"):
        rep(images, HOME_Q14, future, {v: m.astype(np.uint8) for v, m in masks.items()})
    with pytest.raises(ValueError, match="plane_z"):
        SceneReprojector(cameras, plane_z=float("nan"))
    with pytest.raises(ValueError, match="interpolation"):
        SceneReprojector(cameras, interpolation="cubic")


# ---------------------------------------------------------------------- the simulated rig


def test_prior_beats_frozen_on_the_sim_rig_at_frame_15() -> None:
    from pilworld.bench.reprojection import run_reprojection_bench

    result = run_reprojection_bench(RIG, quick=True)
    pooled = result["wrists_pooled"]
    assert pooled["k"][-1] == 15
    assert pooled["gain_db"][-1] > 1.5, pooled
    assert result["plane_breaks"]["table"]["gain_db"] > 3.0  # where the plane holds, it wins clearly
    assert 0.4 < pooled["fraction"][-1] < 1.0
