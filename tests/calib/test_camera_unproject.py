"""Tests for CameraModel.unproject and CameraModel.backproject_to_plane: exact inverses of project()."""

from __future__ import annotations

import math
from dataclasses import replace
from typing import Any

import cv2
import numpy as np
import pytest

from calib.camera_model import CameraModel
from tests.calib.opencv_compat import undistort_points_iter

from .coefficients import REALISTIC, random_dist

# The head camera of the dual-arm rig at the simulator's default resolution, and a larger one.
HEAD = CameraModel.look_at(
    eye=(-0.75, 0.0, 0.7), target=(0.05, 0.0, 0.0), up=(0, 0, 1), fovy_deg=65, width=128, height=128
)
LOOK_ATS = [
    HEAD,
    CameraModel.look_at(eye=(0.3, -0.9, 1.1), target=(0.0, 0.1, 0.0), up=(0, 0, 1), fovy_deg=50, width=640, height=480),
    CameraModel.look_at(eye=(0.02, 0.01, 1.3), target=(0.0, 0.0, 0.0), up=(1, 0, 0), fovy_deg=80, width=96, height=160),
]


def camera_points(cam: CameraModel, xy: np.ndarray, depth: np.ndarray) -> np.ndarray:
    """Base-frame points whose undistorted normalized coordinates are ``xy`` (N, 2) at depths (N,)."""
    p_cam = np.concatenate([xy * depth[:, None], depth[:, None]], axis=1)
    T_base_cam = np.linalg.inv(cam.T_cam_base)
    return np.asarray(p_cam @ T_base_cam[:3, :3].T + T_base_cam[:3, 3], dtype=np.float64)


def unit(v: np.ndarray) -> np.ndarray:
    return np.asarray(v / np.linalg.norm(v, axis=-1, keepdims=True), dtype=np.float64)


def disc(rng: np.random.Generator, n: int, radius: float) -> np.ndarray:
    """``n`` points uniformly in the disc of ``radius`` (normalized image coordinates)."""
    r = radius * np.sqrt(rng.uniform(0.0, 1.0, n))
    phi = rng.uniform(0.0, 2.0 * math.pi, n)
    return np.stack([r * np.cos(phi), r * np.sin(phi)], axis=1)


def table_points(rng: np.random.Generator, n: int, z: float) -> np.ndarray:
    return np.stack([rng.uniform(-0.4, 0.5, n), rng.uniform(-0.5, 0.5, n), np.full(n, z)], axis=1)


# ---------------------------------------------------------------------- look_at (pinhole) cameras


@pytest.mark.parametrize("cam", LOOK_ATS, ids=["head128", "oblique640x480", "topdown96x160"])
@pytest.mark.parametrize("z", [0.0, 0.02, 0.11])
def test_look_at_round_trip_on_table_planes(cam: CameraModel, z: float) -> None:
    rng = np.random.default_rng(0)
    pts = table_points(rng, 4000, z)
    uv, visible = cam.project(pts)
    assert visible.sum() > 500
    pts, uv = pts[visible], uv[visible]

    back, valid = cam.backproject_to_plane(uv, z)
    assert valid.all()
    np.testing.assert_allclose(back, pts, rtol=0, atol=1e-9)
    assert (back[:, 2] == z).all()

    rays = cam.unproject(uv)
    np.testing.assert_allclose(np.linalg.norm(rays, axis=-1), 1.0, rtol=0, atol=1e-15)
    np.testing.assert_allclose(rays, unit(cam.points_to_camera(pts)), rtol=0, atol=1e-12)
    # Any point along the ray projects back onto the same pixel.
    centre = cam.camera_center_in_base()
    along = centre + 0.83 * (rays @ cam.T_cam_base[:3, :3])
    uv2, _ = cam.project(along)
    assert float(np.abs(uv2 - uv).max()) <= 1e-6


def test_pixel_centre_convention_matches_project() -> None:
    cam = HEAD
    # The principal point of a look_at camera is the image centre ((w - 1) / 2, (h - 1) / 2).
    np.testing.assert_allclose(cam.unproject([63.5, 63.5]), [0.0, 0.0, 1.0], atol=1e-15)
    # The outer edges of the image are at -0.5 and w - 0.5: symmetric about the optical axis, and the
    # vertical edges span exactly fovy.
    top, bottom = cam.unproject([[63.5, -0.5], [63.5, 127.5]])
    assert math.degrees(math.acos(float(top @ bottom))) == pytest.approx(65.0, abs=1e-12)
    left, right = cam.unproject([[-0.5, 63.5], [127.5, 63.5]])
    assert left[0] == pytest.approx(-right[0], abs=1e-15)
    # Integer pixels are pixel centres in both directions of the mapping.
    target_uv, _ = cam.project([0.05, 0.0, 0.0])
    np.testing.assert_allclose(target_uv, [63.5, 63.5], atol=1e-12)
    p, ok = cam.backproject_to_plane([63.5, 63.5])
    assert ok
    np.testing.assert_allclose(p, [0.05, 0.0, 0.0], atol=1e-15)


def test_image_x_axis_points_right_and_v_down() -> None:
    cam = HEAD  # looks along +x from x = -0.75: image right is -y, image down is towards the camera
    (p_right, p_left, p_down), ok = cam.backproject_to_plane([[100.0, 63.5], [20.0, 63.5], [63.5, 120.0]])
    assert ok.all()
    assert p_right[1] < 0.0 < p_left[1]
    assert p_down[0] < 0.05


# ---------------------------------------------------------------------- distorted models


def general_camera(dist: Any, skew: float = 0.0, seed: int = 0) -> CameraModel:
    """A 640x480 distorted camera looking down at the table from an oblique pose."""
    base = CameraModel.look_at(
        eye=(-0.6, 0.2, 0.9), target=(0.1, -0.05, 0.0), up=(0, 0, 1), fovy_deg=60, width=640, height=480
    )
    rng = np.random.default_rng(seed)
    K = base.K.copy()
    K[0, 0] *= 1.0 + rng.uniform(-0.02, 0.02)
    K[1, 1] *= 1.0 + rng.uniform(-0.02, 0.02)
    K[0, 2] += rng.uniform(-8.0, 8.0)
    K[1, 2] += rng.uniform(-8.0, 8.0)
    K[0, 1] = skew
    return replace(base, K=K, dist=np.asarray(dist, dtype=np.float64))


DISTORTED = [
    pytest.param(REALISTIC[5], 0.0, id="5-realistic"),
    pytest.param(REALISTIC[8], 0.0, id="8-realistic"),
    pytest.param(REALISTIC[5], 1.7, id="5-realistic-skew"),
    pytest.param(REALISTIC[8], -2.3, id="8-realistic-skew"),
    *(
        pytest.param(random_dist(np.random.default_rng(s), n), 0.0, id=f"{n}-random{s}")
        for n in (5, 8)
        for s in (1, 2, 3)
    ),
    pytest.param(REALISTIC[12], 0.0, id="12-realistic"),
    pytest.param(REALISTIC[14], 0.0, id="14-realistic-tilt"),
]


@pytest.mark.parametrize(("dist", "skew"), DISTORTED)
def test_distorted_round_trip_inside_monotonic_region(dist: Any, skew: float) -> None:
    cam = general_camera(dist, skew)
    # Rays anywhere inside the valid field of view (up to 95 % of the monotonic radius, and not
    # wider than ~110° so that depths stay reasonable), in or out of the image.
    radius = min(0.95 * cam.max_valid_radius, 1.5)
    rng = np.random.default_rng(7)
    xy = disc(rng, 3000, radius)
    depth = np.asarray(rng.uniform(0.3, 2.0, xy.shape[0]), dtype=np.float64)
    pts = camera_points(cam, xy, depth)
    proj = cam.project_detailed(pts)
    assert proj.in_valid_fov.all()
    rays = cam.unproject(proj.uv)
    truth = unit(cam.points_to_camera(pts))
    # Over the whole valid field of view a ray is either right or NaN, never wrong: near a pole of the
    # rational model (8-random2: distorted radius > 1.43, ~600 px off-centre) Newton started at the
    # distorted point does not converge and DistortionModel.undistort reports NaN.
    solved = np.asarray(np.isfinite(rays).all(axis=1))
    np.testing.assert_allclose(rays[solved], truth[solved], rtol=0, atol=1e-10)
    # Everywhere in the image and a margin of 1/8 of its size around it, it is solved.
    near = (np.abs(proj.uv - [319.5, 239.5]) < [400.0, 300.0]).all(axis=1)
    assert near.sum() > 1000
    assert solved[near].all()
    pts, uv, rays, depth = pts[solved], proj.uv[solved], rays[solved], depth[solved]

    uv2, _ = cam.project(cam.camera_center_in_base() + (rays * depth[:, None]) @ cam.T_cam_base[:3, :3])
    assert float(np.abs(uv2 - uv).max()) <= 1e-6

    # Back-projection onto the horizontal plane through each point recovers it (per-point plane height).
    back, valid = cam.backproject_to_plane(uv, pts[:, 2])
    # Rays nearly parallel to the plane amplify round-off; keep those hitting within 5 m.
    dirs = rays @ cam.T_cam_base[:3, :3]
    steep = np.abs(dirs[:, 2]) > 0.2
    assert valid[steep].all()
    np.testing.assert_allclose(back[steep], pts[steep], rtol=0, atol=1e-9)


@pytest.mark.parametrize("n", [5, 8])
def test_distorted_table_round_trip_visible_pixels(n: int) -> None:
    cam = general_camera(REALISTIC[n], seed=n)
    rng = np.random.default_rng(n)
    pts = table_points(rng, 5000, 0.0)
    uv, visible = cam.project(pts)
    assert visible.sum() > 1000
    back, valid = cam.backproject_to_plane(uv[visible])
    assert valid.all()
    np.testing.assert_allclose(back, pts[visible], rtol=0, atol=1e-9)


def test_rays_agree_with_opencv_undistort_points_iter() -> None:
    cam = general_camera(REALISTIC[5])
    rng = np.random.default_rng(11)
    uv = np.stack([rng.uniform(-0.5, 639.5, 2000), rng.uniform(-0.5, 479.5, 2000)], axis=1)
    criteria = (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 200, 1e-15)
    ref = undistort_points_iter(uv[:, None, :], cam.K, cam.dist, criteria)[:, 0, :]
    ref_rays = unit(np.concatenate([ref, np.ones((ref.shape[0], 1))], axis=1))
    np.testing.assert_allclose(cam.unproject(uv), ref_rays, rtol=0, atol=1e-9)


def test_pixel_beyond_monotonic_radius_has_no_ray() -> None:
    # g(r) = r (1 - 0.5 r²) peaks at r = sqrt(2/3) with g = 0.544; a pixel at distorted radius 0.6 has
    # no preimage inside the valid field of view.
    K = np.array([[500.0, 0.0, 319.5], [0.0, 500.0, 239.5], [0.0, 0.0, 1.0]])
    cam = CameraModel(K=K, dist=np.array([-0.5, 0.0, 0.0, 0.0]), T_cam_base=np.eye(4), width=640, height=480)
    uv = [[319.5 + 0.6 * 500.0, 239.5], [319.5 + 0.4 * 500.0, 239.5]]
    rays = cam.unproject(uv)
    assert np.isnan(rays[0]).all()
    assert np.isfinite(rays[1]).all()
    points, valid = cam.backproject_to_plane(uv, 1.0)  # the camera frame is the base frame: plane Z_c = 1
    assert valid.tolist() == [False, True]
    assert np.isnan(points[0]).all()
    assert points[1][2] == 1.0


def test_tilt_flipped_pixels_have_no_ray() -> None:
    # A strong tilt makes the homography's denominator w = 0 cross the field of view; pixels whose only
    # preimage has w <= 0 are never produced by project().
    cam = CameraModel(K=np.eye(3), dist=np.array([0.0] * 12 + [0.6, 0.0]), T_cam_base=np.eye(4), width=10, height=10)
    ray = cam.unproject([[0.0, 0.0], [0.0, 40.0], [0.0, -40.0]])
    ok = np.asarray(np.isfinite(ray).all(axis=1))
    assert ok[0]
    assert not ok.all()
    uv, visible = cam.project(ray[ok])
    assert visible.shape == (int(ok.sum()),)
    np.testing.assert_allclose(uv, np.array([[0.0, 0.0], [0.0, 40.0], [0.0, -40.0]])[ok], atol=1e-6)


# ---------------------------------------------------------------------- plane validity and shapes


def test_parallel_and_behind_rays_are_invalid() -> None:
    # Looking horizontally from 1 m above the table: the centre row is parallel to z = 0, rows above it
    # hit the plane behind the camera, rows below it in front.
    cam = CameraModel.look_at(eye=(0, 0, 1), target=(1, 0, 1), up=(0, 0, 1), fovy_deg=60, width=64, height=64)
    uv = [[31.5, 31.5], [31.5, 10.0], [31.5, 50.0]]
    points, valid = cam.backproject_to_plane(uv)
    assert valid.tolist() == [False, False, True]
    assert np.isnan(points[:2]).all()
    assert points[2][0] > 0.0
    # A plane above the camera: now only the upper rows hit it in front.
    _, valid_up = cam.backproject_to_plane(uv, 1.5)
    assert valid_up.tolist() == [False, True, False]


def test_plane_through_the_camera_is_invalid() -> None:
    _, valid = HEAD.backproject_to_plane([[10.0, 10.0], [63.5, 63.5]], 0.7)
    assert not valid.any()


def test_batch_shapes_and_per_pixel_heights() -> None:
    rng = np.random.default_rng(5)
    uv = rng.uniform(30.0, 100.0, (2, 3, 2))
    assert HEAD.unproject(uv).shape == (2, 3, 3)
    assert HEAD.unproject(uv[0, 0]).shape == (3,)
    assert HEAD.unproject(np.zeros((0, 2))).shape == (0, 3)
    points, valid = HEAD.backproject_to_plane(uv)
    assert points.shape == (2, 3, 3) and valid.shape == (2, 3)
    z = np.array([0.0, 0.02, 0.04])  # broadcasts along the last batch axis
    points_z, valid_z = HEAD.backproject_to_plane(uv, z)
    assert valid_z.all()
    np.testing.assert_array_equal(points_z[..., 2], np.broadcast_to(z, (2, 3)))
    p0, ok0 = HEAD.backproject_to_plane(uv[0, 0])
    assert p0.shape == (3,) and ok0.shape == () and bool(ok0)
    # uv given as integer pixel indices (e.g. from np.nonzero) works as float pixel centres.
    np.testing.assert_array_equal(HEAD.unproject(np.array([[5, 7]])), HEAD.unproject([[5.0, 7.0]]))


@pytest.mark.parametrize(
    "bad",
    [[1.0, 2.0, 3.0], 5.0, [[1.0], [2.0]], [np.nan, 1.0], [[1.0, np.inf]], "ab", [[1.0, 2.0], [3.0]]],
    ids=["len3", "scalar", "col", "nan", "inf", "str", "ragged"],
)
def test_bad_uv_raises_naming_uv(bad: Any) -> None:
    with pytest.raises(ValueError, match=r"\buv\b"):
        HEAD.unproject(bad)
    with pytest.raises(ValueError, match=r"\buv\b"):
        HEAD.backproject_to_plane(bad)


@pytest.mark.parametrize("bad", [np.nan, [0.0, np.inf], [0.0, 0.1, 0.2], "x", [[0.0], [0.1], [0.2]]])
def test_bad_z_raises_naming_z(bad: Any) -> None:
    with pytest.raises(ValueError, match=r"\bz\b"):
        HEAD.backproject_to_plane([[1.0, 2.0], [3.0, 4.0]], bad)
