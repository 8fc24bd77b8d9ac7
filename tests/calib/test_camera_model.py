"""Tests for calib.camera_model.CameraModel: projection vs OpenCV, visibility, look_at, resize, YAML."""

from __future__ import annotations

import math
import re
import warnings
from pathlib import Path
from typing import Any

import cv2
import numpy as np
import pytest
import yaml

from calib.camera_model import FORMAT, NEAR_Z, CameraModel
from calib.distortion import distort_normalized, undistort_normalized

from .coefficients import REALISTIC, random_dist

K0 = np.array([[612.3, 0.0, 318.7], [0.0, 609.8, 241.2], [0.0, 0.0, 1.0]])
W, H = 640, 480


def random_rigid(rng: np.random.Generator) -> np.ndarray:
    R, _ = cv2.Rodrigues(rng.normal(size=3))
    T = np.eye(4)
    T[:3, :3] = R
    T[:3, 3] = rng.uniform(-1.0, 1.0, 3)
    return T


def make_camera(dist: Any = (), T: np.ndarray | None = None, K: np.ndarray = K0, **kw: Any) -> CameraModel:
    return CameraModel(
        K=K, dist=np.asarray(dist, dtype=float), T_cam_base=np.eye(4) if T is None else T, width=W, height=H, **kw
    )


def to_base(cam: CameraModel, p_cam: np.ndarray) -> np.ndarray:
    """Camera-frame points (N, 3) -> base-frame points, with an independently computed inverse."""
    T_base_cam = np.linalg.inv(cam.T_cam_base)
    return np.asarray(p_cam @ T_base_cam[:3, :3].T + T_base_cam[:3, 3], dtype=np.float64)


def cv2_project(cam: CameraModel, p_base: np.ndarray) -> np.ndarray:
    rvec, _ = cv2.Rodrigues(cam.T_cam_base[:3, :3])
    tvec = cam.T_cam_base[:3, 3]
    dist = cam.dist if cam.dist.size else None
    out, _ = cv2.projectPoints(p_base, rvec, tvec, cam.K, dist)
    return np.asarray(out[:, 0, :], dtype=np.float64)


def point_for_pixel(cam: CameraModel, u: float, v: float, depth: float = 1.7) -> np.ndarray:
    """A base-frame point that projects to (u, v): invert K, undistort, scale the ray to ``depth``."""
    (fx, s, cx), (_, fy, cy) = cam.K[0], cam.K[1]
    yd = (v - cy) / fy
    xd = (u - cx - s * yd) / fx
    x, y = undistort_normalized([xd, yd], cam.dist)
    return to_base(cam, np.array([[x * depth, y * depth, depth]])).reshape(3)


# ---------------------------------------------------------------------------- projection vs OpenCV


@pytest.mark.parametrize("n", [0, 4, 5, 8, 12, 14])
@pytest.mark.parametrize("kind", ["realistic", "random"])
def test_project_matches_opencv(n: int, kind: str) -> None:
    rng = np.random.default_rng(n + (100 if kind == "random" else 0))
    dist = np.array(REALISTIC[n]) if kind == "realistic" else random_dist(rng, n)
    cam = make_camera(dist, T=random_rigid(rng))
    # 2000 points in front of the camera within its valid (monotonic) field of view, up to ~52° off axis.
    radius = min(0.95 * cam.max_valid_radius, 1.3)
    r = radius * np.sqrt(rng.uniform(size=2000))
    th = rng.uniform(0.0, 2.0 * np.pi, 2000)
    z = rng.uniform(0.2, 4.0, 2000)
    p_cam = np.stack([r * np.cos(th) * z, r * np.sin(th) * z, z], axis=-1)
    p_base = to_base(cam, p_cam)

    uv, visible = cam.project(p_base)
    np.testing.assert_allclose(uv, cv2_project(cam, p_base), rtol=0, atol=1e-6)

    det = cam.project_detailed(p_base)
    assert det.in_front.all() and det.in_valid_fov.all()
    np.testing.assert_array_equal(det.uv, uv)
    np.testing.assert_array_equal(det.visible, visible)
    np.testing.assert_allclose(det.depth, z, rtol=0, atol=1e-12)
    expected_in_image = (uv[:, 0] >= -0.5) & (uv[:, 0] < W - 0.5) & (uv[:, 1] >= -0.5) & (uv[:, 1] < H - 0.5)
    np.testing.assert_array_equal(visible, expected_in_image)
    assert 0 < visible.sum() < len(visible)  # the sample straddles the image border


def test_skew_is_applied_as_matrix_product() -> None:
    # cv2.projectPoints ignores K[0][1]; we honour it: u = fx x'' + s y'' + cx.
    K = K0.copy()
    K[0, 1] = 3.5
    dist = np.array(REALISTIC[5])
    cam = make_camera(dist, K=K)
    rng = np.random.default_rng(5)
    p = np.c_[rng.uniform(-0.4, 0.4, (50, 2)), np.ones(50)]
    xd, yd = distort_normalized(p[:, :2], dist).T
    uv, _ = cam.project(p)
    np.testing.assert_allclose(uv[:, 0], K[0, 0] * xd + 3.5 * yd + K[0, 2], rtol=0, atol=1e-9)
    np.testing.assert_allclose(uv[:, 1], K[1, 1] * yd + K[1, 2], rtol=0, atol=1e-9)


def test_batch_shapes() -> None:
    cam = make_camera(REALISTIC[5], T=random_rigid(np.random.default_rng(1)))
    pts = to_base(cam, np.c_[np.random.default_rng(2).uniform(-0.3, 0.3, (24, 2)), np.full(24, 1.5)])
    uv, vis = cam.project(pts.reshape(2, 3, 4, 3))
    assert uv.shape == (2, 3, 4, 2) and vis.shape == (2, 3, 4) and vis.dtype == np.bool_
    flat_uv, flat_vis = cam.project(pts)
    np.testing.assert_array_equal(uv.reshape(-1, 2), flat_uv)
    np.testing.assert_array_equal(vis.reshape(-1), flat_vis)
    uv1, vis1 = cam.project(pts[0].tolist())
    assert uv1.shape == (2,) and vis1.shape == ()
    np.testing.assert_allclose(uv1, flat_uv[0], rtol=0, atol=1e-9)  # BLAS may round differently
    uv0, vis0 = cam.project(np.zeros((0, 3)))
    assert uv0.shape == (0, 2) and vis0.shape == (0,)
    det = cam.project_detailed(pts.reshape(4, 6, 3))
    for arr in (det.depth, det.in_front, det.in_valid_fov, det.in_image, det.visible):
        assert arr.shape == (4, 6)


@pytest.mark.parametrize("bad", [np.zeros((5, 2)), np.zeros(4), 3.0, [[0, 0, np.nan]], [[np.inf, 0, 1]], "xyz"])
def test_project_rejects_bad_points(bad: Any) -> None:
    cam = make_camera()
    with pytest.raises(ValueError, match="points"):
        cam.project(bad)


# ---------------------------------------------------------------------------- visibility


@pytest.mark.parametrize("n", [0, 5, 12, 14])
def test_points_not_in_front_are_invisible_with_finite_uv(n: int) -> None:
    cam = make_camera(REALISTIC[n] if n != 12 else [-0.5, 0, 0, 0, 0, 0, 0, 0, 1e-3, 0, 0, 0])
    p_cam = np.array(
        [
            [0.0, 0.0, -1.0],  # straight behind
            [0.5, 0.2, -2.0],
            [1.0, 1.0, 0.0],  # in the camera plane
            [0.0, 0.0, 0.0],  # at the optical centre
            [0.3, -0.1, NEAR_Z / 2],  # closer than the near limit
            [0.3, -0.1, NEAR_Z],  # the limit itself is excluded
            [1e3, -1e3, -1e-3],
            [-1e4, 2e4, -5e3],
        ]
    )
    p = to_base(cam, p_cam)
    with warnings.catch_warnings(), np.errstate(divide="raise", over="raise", invalid="raise"):
        warnings.simplefilter("error")
        det = cam.project_detailed(p)
        uv, vis = cam.project(p)
    assert np.isfinite(uv).all() and np.isfinite(det.uv).all()
    assert not vis.any() and not det.visible.any()
    assert not det.in_front.any() and not det.in_valid_fov.any()
    np.testing.assert_allclose(det.depth, p_cam[:, 2], rtol=0, atol=1e-9)


def test_exact_pixel_centre_borders_pinhole() -> None:
    # fx = 512 and cx = 319.5 make the border pixels exactly representable: u = 512 x + 319.5.
    K = np.array([[512.0, 0.0, 319.5], [0.0, 512.0, 239.5], [0.0, 0.0, 1.0]])
    cam = make_camera(K=K)
    tiny = 2.0**-40
    cases = {
        (-320.0, 0.0): True,  # u = -0.5: left edge of pixel 0, inside
        (-320.0 - 1e-6, 0.0): False,
        (320.0, 0.0): False,  # u = 639.5: right edge of pixel 639, outside
        (320.0 - tiny, 0.0): True,
        (0.0, -240.0): True,  # v = -0.5
        (0.0, -240.0 - 1e-6): False,
        (0.0, 240.0): False,  # v = 479.5
        (0.0, 240.0 - tiny): True,
    }
    pts = np.array([[du / 512.0, dv / 512.0, 1.0] for du, dv in cases])
    uv, vis = cam.project(pts)
    np.testing.assert_array_equal(uv[[0, 2, 4, 6]], [[-0.5, 239.5], [639.5, 239.5], [319.5, -0.5], [319.5, 479.5]])
    assert vis.tolist() == list(cases.values())


@pytest.mark.parametrize("n", [0, 5, 8, 14])
def test_just_inside_and_outside_each_border(n: int) -> None:
    cam = make_camera(REALISTIC[n], T=random_rigid(np.random.default_rng(n)))
    eps = 1e-4  # px; the pixel -> point -> pixel round trip is accurate to ~1e-9 px
    mid_u, mid_v = 300.2, 250.7
    inside = [(-0.5 + eps, mid_v), (W - 0.5 - eps, mid_v), (mid_u, -0.5 + eps), (mid_u, H - 0.5 - eps)]
    outside = [(-0.5 - eps, mid_v), (W - 0.5 + eps, mid_v), (mid_u, -0.5 - eps), (mid_u, H - 0.5 + eps)]
    for corner in [(-0.5 + eps, -0.5 + eps), (W - 0.5 - eps, H - 0.5 - eps)]:
        inside.append(corner)
    pts_in = np.array([point_for_pixel(cam, u, v) for u, v in inside])
    pts_out = np.array([point_for_pixel(cam, u, v) for u, v in outside])
    uv_in, vis_in = cam.project(pts_in)
    uv_out, vis_out = cam.project(pts_out)
    np.testing.assert_allclose(uv_in, inside, rtol=0, atol=1e-6)
    np.testing.assert_allclose(uv_out, outside, rtol=0, atol=1e-6)
    assert vis_in.all()
    assert not vis_out.any()
    det = cam.project_detailed(pts_out)
    assert det.in_front.all() and det.in_valid_fov.all() and not det.in_image.any()


def fold_camera() -> CameraModel:
    # g(r) = r (1 - 0.5 r²) peaks at r = sqrt(2/3) ≈ 0.816 and then folds back towards the centre.
    K = np.array([[500.0, 0.0, 319.5], [0.0, 500.0, 239.5], [0.0, 0.0, 1.0]])
    return make_camera([-0.5, 0.0, 0.0, 0.0, 0.0], K=K)


def test_point_far_outside_fov_that_folds_back_is_not_visible() -> None:
    cam = fold_camera()
    assert cam.max_valid_radius == pytest.approx(math.sqrt(2.0 / 3.0))
    # r ≈ 1.2, 1.35 and 1.4; the last one lands 14 px from the image centre.
    far = np.array([[1.2, 0.1, 1.0], [-1.0, -0.9, 1.0], [1.4, 0.0, 1.0]])
    naive = cv2_project(cam, far)
    # Make sure the scenario is real: the raw polynomial puts these points inside the image.
    assert ((naive >= -0.5) & (naive < [W - 0.5, H - 0.5])).all()
    uv, vis = cam.project(far)
    det = cam.project_detailed(far)
    assert not vis.any()
    assert det.in_front.all() and not det.in_valid_fov.any()
    assert np.isfinite(uv).all()
    # Just inside the monotonic radius the same lens is trusted and the point is visible.
    near_edge = np.array([[0.8, 0.0, 1.0]])
    uv_ok, vis_ok = cam.project(near_edge)
    assert vis_ok.all()
    np.testing.assert_allclose(uv_ok, cv2_project(cam, near_edge), rtol=0, atol=1e-9)


def test_uv_outside_valid_fov_keeps_direction_and_grows_with_angle() -> None:
    cam = fold_camera()
    r_max = cam.max_valid_radius
    r = np.concatenate([np.linspace(0.05, 20.0, 4000), r_max * (1 + np.array([-1e-7, 0.0, 1e-7]))])
    r.sort()
    direction = np.array([0.6, -0.8])
    pts = np.c_[np.outer(r, direction), np.ones_like(r)]
    det = cam.project_detailed(pts)
    offset = det.uv - cam.K[:2, 2]
    dist_px = np.linalg.norm(offset, axis=1)
    assert (np.diff(dist_px) >= 0).all()  # never folds back
    np.testing.assert_allclose(offset / dist_px[:, None], np.tile(direction, (len(r), 1)), atol=1e-12)
    np.testing.assert_array_equal(det.in_valid_fov, r < r_max)
    jump = np.abs(np.diff(dist_px[(r > r_max * 0.999) & (r < r_max * 1.001)])).max()
    assert jump < 1e-3  # continuous across the edge of the valid field of view


# ---------------------------------------------------------------------------- frames, look_at, resize


def test_points_to_camera_and_center() -> None:
    rng = np.random.default_rng(11)
    cam = make_camera(REALISTIC[5], T=random_rigid(rng))
    p = rng.normal(size=(7, 3))
    expected = p @ cam.T_cam_base[:3, :3].T + cam.T_cam_base[:3, 3]
    np.testing.assert_allclose(cam.points_to_camera(p), expected, atol=1e-12)
    assert cam.points_to_camera(p.reshape(7, 1, 3)).shape == (7, 1, 3)
    c = cam.camera_center_in_base()
    np.testing.assert_allclose(cam.points_to_camera(c), 0.0, atol=1e-12)
    np.testing.assert_allclose(c, np.linalg.inv(cam.T_cam_base)[:3, 3], atol=1e-12)


def test_look_at_orientation() -> None:
    # Camera south of the origin looking north (+y) with z up: +x (east) is to its right.
    cam = CameraModel.look_at(eye=[0, -1, 0], target=[0, 0, 0], up=[0, 0, 1], fovy_deg=60, width=W, height=H)
    centre = ((W - 1) / 2, (H - 1) / 2)
    uv, vis = cam.project([[0.0, 0.0, 0.0], [0.1, 0.0, 0.0], [0.0, 0.0, 0.1]])
    np.testing.assert_allclose(uv[0], centre, atol=1e-9)
    assert uv[1, 0] > centre[0] + 1 and uv[1, 1] == pytest.approx(centre[1], abs=1e-9)  # right -> larger u
    assert uv[2, 1] < centre[1] - 1 and uv[2, 0] == pytest.approx(centre[0], abs=1e-9)  # up -> smaller v
    assert vis.all()
    # fovy spans the full image height edge to edge: a ray 30° above the axis hits the top edge v = -0.5.
    top_uv, _ = cam.project([0.0, 0.0, math.tan(math.radians(30.0))])
    np.testing.assert_allclose(top_uv, [centre[0], -0.5], atol=1e-9)
    assert cam.K[0, 0] == cam.K[1, 1] and cam.dist.size == 0 and cam.name == "cam_high"
    np.testing.assert_allclose(cam.camera_center_in_base(), [0, -1, 0], atol=1e-15)


def test_look_at_general_pose() -> None:
    eye, target, up = np.array([1.0, -0.5, 1.2]), np.array([0.2, 0.3, 0.1]), np.array([0.0, 0.0, 2.0])
    cam = CameraModel.look_at(eye, target, up, fovy_deg=45.0, width=224, height=160, name="sim")
    fwd = (target - eye) / np.linalg.norm(target - eye)
    right = np.cross(fwd, up)
    right /= np.linalg.norm(right)
    uv, vis = cam.project([target, target + 0.05 * right, target + 0.05 * up, target - 2.0 * (target - eye)])
    np.testing.assert_allclose(uv[0], [111.5, 79.5], atol=1e-9)
    assert uv[1, 0] > uv[0, 0] and uv[2, 1] < uv[0, 1]
    assert vis[:3].all() and not vis[3]  # the last point is behind the eye
    assert cam.name == "sim" and (cam.width, cam.height) == (224, 160)


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        ({"eye": [1, 2, 3], "target": [1, 2, 3]}, "coincide"),
        ({"up": [0, 2, 0]}, "parallel"),  # parallel to the viewing direction (+y)
        ({"up": [0, -1, 0]}, "parallel"),
        ({"up": [0, 0, 0]}, "non-zero"),
        ({"fovy_deg": 0.0}, "fovy_deg"),
        ({"fovy_deg": 180.0}, "fovy_deg"),
        ({"eye": [0, 1]}, "eye"),
        ({"width": 0}, "width"),
    ],
)
def test_look_at_rejects_degenerate_input(kwargs: dict[str, Any], match: str) -> None:
    args: dict[str, Any] = {"eye": [0, -1, 0], "target": [0, 0, 0], "up": [0, 0, 1], "fovy_deg": 60}
    args |= {"width": W, "height": H}
    args |= kwargs
    with pytest.raises(ValueError, match=match):
        CameraModel.look_at(**args)


@pytest.mark.parametrize(("new_w", "new_h"), [(320, 240), (1280, 960), (224, 224), (641, 479)])
def test_resized_scales_pixels_with_pixel_centre_convention(new_w: int, new_h: int) -> None:
    rng = np.random.default_rng(new_w)
    cam = make_camera(REALISTIC[5], T=random_rigid(rng))
    small = cam.resized(new_w, new_h)
    sx, sy = new_w / W, new_h / H
    assert (small.width, small.height) == (new_w, new_h)
    assert small.K[0, 2] == pytest.approx((cam.K[0, 2] + 0.5) * sx - 0.5, abs=1e-12)
    assert small.K[1, 2] == pytest.approx((cam.K[1, 2] + 0.5) * sy - 0.5, abs=1e-12)
    assert small.K[0, 0] == pytest.approx(cam.K[0, 0] * sx) and small.K[1, 1] == pytest.approx(cam.K[1, 1] * sy)
    np.testing.assert_array_equal(small.dist, cam.dist)
    np.testing.assert_array_equal(small.T_cam_base, cam.T_cam_base)
    p = to_base(cam, np.c_[rng.uniform(-0.5, 0.5, (300, 2)), rng.uniform(0.5, 2.0, 300)])
    uv, _ = cam.project(p)
    uv_small, _ = small.project(p)
    np.testing.assert_allclose(uv_small, (uv + 0.5) * [sx, sy] - 0.5, rtol=0, atol=1e-9)
    # The image border maps onto the image border: a point on the left edge of the full image stays on it.
    edge = point_for_pixel(cam, -0.5, 100.0)
    np.testing.assert_allclose(small.project(edge)[0][0], -0.5, atol=1e-6)


def test_with_pose() -> None:
    cam = make_camera(REALISTIC[5])
    T = random_rigid(np.random.default_rng(3))
    moved = cam.with_pose(T)
    np.testing.assert_array_equal(moved.T_cam_base, T)
    np.testing.assert_array_equal(cam.T_cam_base, np.eye(4))
    np.testing.assert_array_equal(moved.K, cam.K)
    assert moved.name == cam.name
    with pytest.raises(ValueError, match="T_cam_base"):
        cam.with_pose(np.diag([1.0, 1.0, -1.0, 1.0]))


# ---------------------------------------------------------------------------- validation, identity


def _valid_kwargs() -> dict[str, Any]:
    return {"K": K0.copy(), "dist": np.array(REALISTIC[5]), "T_cam_base": np.eye(4), "width": W, "height": H}


def _scaled_t() -> np.ndarray:
    T = np.eye(4)
    T[:3, :3] *= 1.001
    return T


def _bad_k(i: int, j: int, value: float) -> np.ndarray:
    K = K0.copy()
    K[i, j] = value
    return K


@pytest.mark.parametrize(
    ("field", "value", "fragment"),
    [
        ("K", np.eye(3)[:2], r"field 'K': expected a 3x3 matrix, got shape \(2, 3\)"),
        ("K", _bad_k(0, 0, -500.0), r"field 'K': fx = K\[0\]\[0\] must be > 0, got -500.0"),
        ("K", _bad_k(1, 1, 0.0), r"field 'K': fy"),
        ("K", _bad_k(2, 2, 2.0), r"field 'K': expected the OpenCV layout"),
        ("K", _bad_k(1, 0, 1.0), r"field 'K': expected the OpenCV layout"),
        ("K", _bad_k(0, 2, np.nan), r"field 'K': entries must be finite"),
        ("K", "not a matrix", r"field 'K'"),
        ("dist", np.zeros(6), r"field 'dist': expected 0, 4, 5, 8, 12 or 14 .* got 6"),
        ("dist", [0.1, np.inf, 0, 0], r"field 'dist': distortion coefficients must be finite"),
        ("T_cam_base", np.eye(3), r"field 'T_cam_base': expected a 4x4 matrix, got shape \(3, 3\)"),
        ("T_cam_base", _scaled_t(), r"field 'T_cam_base': expected a rigid transform"),
        ("T_cam_base", np.diag([1.0, -1.0, 1.0, 1.0]), r"field 'T_cam_base': .*det R = -1"),
        ("T_cam_base", np.vstack([np.eye(4)[:3], [0, 0, 1, 1]]), r"field 'T_cam_base': .*last row"),
        ("width", 0, r"field 'width': expected an integer > 0 \(pixels\), got 0"),
        ("height", 480.0, r"field 'height'"),
        ("height", True, r"field 'height'"),
        ("name", "", r"field 'name'"),
        ("name", 3, r"field 'name'"),
    ],
)
def test_constructor_rejects_invalid_fields(field: str, value: Any, fragment: str) -> None:
    kwargs = _valid_kwargs()
    kwargs[field] = value
    with pytest.raises(ValueError, match=fragment):
        CameraModel(**kwargs)


def test_constructor_accepts_lists_numpy_ints_and_near_rigid() -> None:
    T = np.eye(4)
    T[0, 0] += 2e-7  # within RIGID_ATOL, as printed calibration files are
    # Fields are typed as the stored float64 arrays; converting other inputs at runtime is the point here.
    cam = CameraModel(K=K0.tolist(), dist=[[*REALISTIC[5]]], T_cam_base=T, width=np.int64(W), height=H)  # type: ignore[arg-type]
    assert type(cam.width) is int and cam.dist.shape == (5,) and cam.K.dtype == np.float64


def test_arrays_are_read_only_copies() -> None:
    kwargs = _valid_kwargs()
    cam = CameraModel(**kwargs)
    kwargs["K"][0, 0] = 1.0
    kwargs["dist"][0] = 1.0
    assert cam.K[0, 0] == K0[0, 0] and cam.dist[0] == REALISTIC[5][0]
    for arr in (cam.K, cam.dist, cam.T_cam_base):
        with pytest.raises(ValueError, match="read-only"):
            arr[0] = 0.0


def test_equality_and_hash() -> None:
    a = CameraModel(**_valid_kwargs())
    b = CameraModel(**_valid_kwargs())
    assert a == b and hash(a) == hash(b)
    assert a != a.resized(320, 240)
    assert a != CameraModel(**(_valid_kwargs() | {"name": "other"}))
    assert a != CameraModel(**(_valid_kwargs() | {"dist": np.array(REALISTIC[5][:4])}))
    assert len({a, b, a.resized(320, 240)}) == 2


# ---------------------------------------------------------------------------- YAML


def _awkward_camera() -> CameraModel:
    rng = np.random.default_rng(42)
    K = np.array([[600.0 + 0.1 + 0.2, 0.1 + 0.2, 1 / 3 * 960], [0.0, 598.123456789012345, 240.0 + 1e-13], [0, 0, 1]])
    return CameraModel(K=K, dist=random_dist(rng, 14) * (1 + 1e-15), T_cam_base=random_rigid(rng), width=W, height=H)


def test_yaml_round_trip_is_exact(tmp_path: Path) -> None:
    cam = _awkward_camera()
    path = tmp_path / "cam.yaml"
    cam.to_yaml(path)
    text = path.read_text(encoding="utf-8")
    assert f"format: {FORMAT}" in text and "name: cam_high" in text
    loaded = CameraModel.from_yaml(path)
    assert loaded == cam
    for name in ("K", "dist", "T_cam_base"):
        assert getattr(loaded, name).tobytes() == getattr(cam, name).tobytes()
    assert (loaded.width, loaded.height, loaded.name) == (W, H, "cam_high")
    assert not list(tmp_path.glob("*.tmp"))
    # And the dict form, through a YAML dump (to_dict must hold plain YAML-safe types only).
    assert CameraModel.from_dict(yaml.safe_load(yaml.safe_dump(cam.to_dict()))) == cam


def test_yaml_round_trip_without_distortion(tmp_path: Path) -> None:
    cam = CameraModel.look_at([0.5, -1.0, 0.8], [0, 0, 0], [0, 0, 1], 55.0, 224, 224, name="cam_sim")
    cam.to_yaml(tmp_path / "sim.yaml")
    assert CameraModel.from_yaml(tmp_path / "sim.yaml") == cam


def test_hand_written_yaml_loads(tmp_path: Path) -> None:
    path = tmp_path / "hand.yaml"
    path.write_text(
        "format: pilworld.camera_model/v1\n"
        "image_size: {width: 640, height: 480}\n"
        "K: [[600, 0, 320], [0, 600, 240], [0, 0, 1]]\n"
        "dist: [-0.1, 1e-5, 0, 0]   # PyYAML reads 1e-5 (no dot) as a string\n"
        "T_cam_base: [[1, 0, 0, 0], [0, 1, 0, 0], [0, 0, 1, 0.5], [0, 0, 0, 1]]\n",
        encoding="utf-8",
    )
    cam = CameraModel.from_yaml(path)
    assert cam.dist.tolist() == [-0.1, 1e-5, 0.0, 0.0] and cam.name == "cam_high"
    assert cam.T_cam_base[2, 3] == 0.5


def _valid_dict() -> dict[str, Any]:
    return _awkward_camera().to_dict()


def _set(key: str, value: Any) -> Any:
    def mutate(d: dict[str, Any]) -> None:
        d[key] = value

    return mutate


def _drop(key: str) -> Any:
    def mutate(d: dict[str, Any]) -> None:
        del d[key]

    return mutate


def _set_entry(key: str, i: int, j: int, value: Any) -> Any:
    def mutate(d: dict[str, Any]) -> None:
        d[key][i][j] = value

    return mutate


def _scale_rotation(d: dict[str, Any]) -> None:
    d["T_cam_base"] = (np.array(d["T_cam_base"]) @ np.diag([1.01, 1.01, 1.01, 1.0])).tolist()


@pytest.mark.parametrize(
    ("mutate", "fragment"),
    [
        (
            _set("K", [[600.0, 0.0, 320.0], [0.0, 600.0, 240.0]]),
            r"field 'K': expected a 3x3 matrix, got shape \(2, 3\)",
        ),
        (_set("K", [[600.0, 0.0, 320.0], [0.0, 600.0], [0.0, 0.0, 1.0]]), r"field 'K': .*different lengths"),
        (_set("K", "eye(3)"), r"field 'K': expected a 3x3 matrix"),
        (_set_entry("K", 0, 0, -600.0), r"field 'K': fx = K\[0\]\[0\] must be > 0, got -600.0"),
        (_set_entry("K", 1, 1, True), r"field 'K': expected a number, got True"),
        (_set_entry("K", 0, 2, "abc"), r"field 'K': expected a number, got 'abc'"),
        (_set("dist", [0.1, 0.01, 0.0, 0.0, 0.0, 0.0]), r"field 'dist': expected 0, 4, 5, 8, 12 or 14 .* got 6"),
        (_set("dist", 0.1), r"field 'dist': expected a list"),
        (_set("dist", ".nan"), r"field 'dist': expected a list"),
        (_scale_rotation, r"field 'T_cam_base': expected a rigid transform"),
        (_set("T_cam_base", np.eye(3).tolist()), r"field 'T_cam_base': expected a 4x4 matrix, got shape \(3, 3\)"),
        (_set_entry("T_cam_base", 3, 2, 0.5), r"field 'T_cam_base': .*last row"),
        (_drop("K"), r"field 'K': missing"),
        (_drop("dist"), r"field 'dist': missing"),
        (_drop("T_cam_base"), r"field 'T_cam_base': missing"),
        (_drop("image_size"), r"field 'image_size': missing"),
        (_drop("format"), r"field 'format': missing"),
        (_set("format", "pilworld.camera_model/v2"), r"field 'format': expected 'pilworld.camera_model/v1'"),
        (_set("image_size", {"width": 640}), r"field 'image_size'"),
        (_set("image_size", {"width": "640", "height": 480}), r"field 'width': expected an integer > 0"),
        (_set("image_size", {"width": 640, "height": -1}), r"field 'height': expected an integer > 0"),
        (_set("name", ""), r"field 'name'"),
        (_set("distortion", [0.0] * 5), r"unknown field\(s\) 'distortion'"),
    ],
)
def test_invalid_yaml_names_file_and_field(tmp_path: Path, mutate: Any, fragment: str) -> None:
    d = _valid_dict()
    mutate(d)
    path = tmp_path / "cam.yaml"
    path.write_text(yaml.safe_dump(d, sort_keys=False), encoding="utf-8")
    with pytest.raises(ValueError, match=re.escape(str(path)) + ": " + fragment):
        CameraModel.from_yaml(path)


@pytest.mark.parametrize(
    ("text", "fragment"),
    [("- 1\n- 2\n", "expected a mapping"), ("K: [[1, 2\n", "not valid YAML"), ("", "empty")],
)
def test_malformed_yaml_names_file(tmp_path: Path, text: str, fragment: str) -> None:
    path = tmp_path / "broken.yaml"
    path.write_text(text, encoding="utf-8")
    with pytest.raises(ValueError, match=re.escape(str(path)) + ".*" + fragment):
        CameraModel.from_yaml(path)


def test_missing_file_raises_file_not_found_with_path(tmp_path: Path) -> None:
    path = tmp_path / "nope" / "cam.yaml"
    with pytest.raises(FileNotFoundError, match=re.escape(str(path))):
        CameraModel.from_yaml(path)


def test_from_dict_default_source() -> None:
    with pytest.raises(ValueError, match=r"^<dict>: field 'K': missing"):
        CameraModel.from_dict({k: v for k, v in _valid_dict().items() if k != "K"})
