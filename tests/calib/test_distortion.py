"""Tests for calib.distortion: OpenCV's distortion model, its inverse and its monotonic radius."""

from __future__ import annotations

import math

import cv2
import numpy as np
import pytest

from calib.distortion import (
    VALID_COEFFICIENT_COUNTS,
    DistortionModel,
    as_distortion_coefficients,
    distort_normalized,
    max_monotonic_radius,
    tilt_projection_matrix,
    undistort_normalized,
)
from tests.calib.opencv_compat import undistort_points_iter

from .coefficients import REALISTIC, random_dist


def cv2_distort(xy: np.ndarray, dist: np.ndarray) -> np.ndarray:
    """OpenCV's distortion of normalized points: projectPoints with K = I and the identity pose."""
    pts = np.concatenate([xy, np.ones((len(xy), 1))], axis=1)
    out, _ = cv2.projectPoints(pts, np.zeros(3), np.zeros(3), np.eye(3), dist if len(dist) else None)
    return np.asarray(out[:, 0, :], dtype=np.float64)


def disc(rng: np.random.Generator, n: int, radius: float) -> np.ndarray:
    r = radius * np.sqrt(rng.uniform(size=n))
    th = rng.uniform(0.0, 2.0 * np.pi, n)
    return np.stack([r * np.cos(th), r * np.sin(th)], axis=-1)


def radial_g(dist: np.ndarray, r: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """r * radial(r) and the rational denominator, straight from the OpenCV formula."""
    k = np.zeros(14)
    k[: len(dist)] = dist
    s = r * r
    num = 1 + k[0] * s + k[1] * s**2 + k[4] * s**3
    den = 1 + k[5] * s + k[6] * s**2 + k[7] * s**3
    with np.errstate(divide="ignore", invalid="ignore"):  # r may sit exactly on a pole
        return r * num / den, den


# ---------------------------------------------------------------------------- coefficients


@pytest.mark.parametrize("n", VALID_COEFFICIENT_COUNTS)
def test_accepts_opencv_counts(n: int) -> None:
    assert as_distortion_coefficients(np.zeros(n)).shape == (n,)


def test_accepts_calibrate_camera_layout() -> None:
    # cv2.calibrateCamera returns dist as (1, 5).
    assert as_distortion_coefficients(np.array([REALISTIC[5]])).tolist() == REALISTIC[5]
    assert as_distortion_coefficients(None).shape == (0,)


@pytest.mark.parametrize("n", [1, 2, 3, 6, 7, 9, 13, 15])
def test_rejects_other_counts(n: int) -> None:
    with pytest.raises(ValueError, match=rf"dist: expected 0, 4, 5, 8, 12 or 14 .*got {n}"):
        as_distortion_coefficients(np.zeros(n))


@pytest.mark.parametrize("bad", [[np.nan, 0, 0, 0], [0, np.inf, 0, 0, 0], "abc", np.zeros((2, 5))])
def test_rejects_bad_values(bad: object) -> None:
    with pytest.raises(ValueError, match="dist"):
        DistortionModel(bad)  # type: ignore[arg-type]


def test_coefficients_are_read_only_copies() -> None:
    src = np.array(REALISTIC[5])
    model = DistortionModel(src)
    src[0] = 99.0
    assert model.coefficients[0] == REALISTIC[5][0]
    with pytest.raises(ValueError):
        model.coefficients[0] = 1.0


# ---------------------------------------------------------------------------- forward model


@pytest.mark.parametrize("n", VALID_COEFFICIENT_COUNTS)
def test_distort_matches_opencv_realistic(n: int) -> None:
    dist = np.array(REALISTIC[n], dtype=np.float64)
    xy = disc(np.random.default_rng(n), 1000, 1.0)
    np.testing.assert_allclose(distort_normalized(xy, dist), cv2_distort(xy, dist), rtol=0, atol=1e-12)


@pytest.mark.parametrize("n", VALID_COEFFICIENT_COUNTS)
@pytest.mark.parametrize("seed", range(5))
def test_distort_matches_opencv_random(n: int, seed: int) -> None:
    rng = np.random.default_rng(1000 * seed + n)
    dist = random_dist(rng, n)
    xy = disc(rng, 500, 1.2)
    np.testing.assert_allclose(distort_normalized(xy, dist), cv2_distort(xy, dist), rtol=0, atol=1e-12)


@pytest.mark.parametrize("index", range(14))
def test_each_coefficient_alone_matches_opencv(index: int) -> None:
    # Catches a swapped term (e.g. p1/p2 or s1..s4) that a mixed coefficient set could partly mask.
    dist = np.zeros(14)
    dist[index] = 0.05 if index < 12 else 0.2
    xy = disc(np.random.default_rng(index), 300, 1.0)
    np.testing.assert_allclose(distort_normalized(xy, dist), cv2_distort(xy, dist), rtol=0, atol=1e-12)


def test_tilt_matrix_identity_and_opencv_structure() -> None:
    np.testing.assert_array_equal(tilt_projection_matrix(0.0, 0.0), np.eye(3))
    m = tilt_projection_matrix(0.1, -0.2)
    # OpenCV's matTilt = matProjZ * matRotXY keeps the optical axis: [0, 0, 1] maps to a multiple of itself.
    image_of_axis = m @ np.array([0.0, 0.0, 1.0])
    np.testing.assert_allclose(image_of_axis[:2], 0.0, atol=1e-15)


def test_distort_preserves_batch_shape_and_rejects_bad_shape() -> None:
    dist = REALISTIC[5]
    xy = disc(np.random.default_rng(0), 24, 0.5).reshape(2, 3, 4, 2)
    out = distort_normalized(xy, dist)
    assert out.shape == (2, 3, 4, 2)
    np.testing.assert_array_equal(out.reshape(-1, 2), distort_normalized(xy.reshape(-1, 2), dist))
    assert distort_normalized([0.1, 0.2], dist).shape == (2,)
    with pytest.raises(ValueError, match=r"\(\.\.\., 2\)"):
        distort_normalized(np.zeros((4, 3)), dist)


# ---------------------------------------------------------------------------- monotonic radius


def test_max_monotonic_radius_closed_forms() -> None:
    assert max_monotonic_radius([]) == math.inf
    assert max_monotonic_radius(np.zeros(14)) == math.inf
    # g = r (1 - 0.5 r²): g' = 1 - 1.5 r² = 0 at r = sqrt(2/3).
    assert max_monotonic_radius([-0.5, 0, 0, 0]) == pytest.approx(math.sqrt(2.0 / 3.0), rel=1e-12)
    # g = r (1 + k2 r⁴) with k2 < 0: g' = 1 + 5 k2 r⁴ = 0 at r = (-1 / (5 k2))^(1/4).
    assert max_monotonic_radius([0, -0.1, 0, 0]) == pytest.approx(2.0**0.25, rel=1e-12)
    # g = r / (1 - 0.5 r²) increases everywhere up to its pole at r = sqrt(2).
    assert max_monotonic_radius([0, 0, 0, 0, 0, -0.5, 0, 0]) == pytest.approx(math.sqrt(2.0), rel=1e-12)
    # Pincushion (k1 > 0, k2 > 0) never turns around; tangential/prism/tilt terms are ignored.
    assert max_monotonic_radius([0.1, 0.05, 0.01, 0.01, 0, 0, 0, 0, 0.01, 0, 0, 0, 0.1, 0.1]) == math.inf
    # A typical barrel fit turns around only far outside its field of view.
    assert max_monotonic_radius(REALISTIC[5]) > 1.5


@pytest.mark.parametrize("seed", range(40))
def test_max_monotonic_radius_agrees_with_sampling(seed: int) -> None:
    rng = np.random.default_rng(seed)
    # Mix realistic and deliberately strong coefficients so that many cases have a finite radius.
    strength = 1.0 if seed % 2 == 0 else 8.0
    dist = random_dist(rng, 8) * np.array([strength] * 2 + [1] * 2 + [strength] * 4)
    r_max = max_monotonic_radius(dist)
    upper = min(r_max, 10.0)
    r = np.linspace(0.0, upper * (1 - 1e-6), 200_001)
    g, den = radial_g(dist, r)
    assert (den > 0).all()
    assert (np.diff(g) > 0).all(), f"g not increasing below r_max = {r_max} for {dist}"
    if math.isfinite(r_max):
        # Just beyond r_max the mapping has turned around (g decreases) or hit the rational pole.
        after = np.linspace(r_max, r_max * 1.01, 2001)
        g_after, den_after = radial_g(dist, after)
        assert (np.diff(g_after) < 0).any() or (den_after <= 0).any()


def test_cached_radius_is_consistent() -> None:
    model = DistortionModel([-0.5, 0, 0, 0])
    assert model.max_monotonic_radius == model.max_monotonic_radius == max_monotonic_radius([-0.5, 0, 0, 0])


# ---------------------------------------------------------------------------- inverse


@pytest.mark.parametrize("n", VALID_COEFFICIENT_COUNTS)
@pytest.mark.parametrize("seed", range(3))
def test_undistort_inverts_distort(n: int, seed: int) -> None:
    rng = np.random.default_rng(seed * 100 + n)
    for dist in (np.array(REALISTIC[n]), random_dist(rng, n)):
        radius = 0.8 * min(max_monotonic_radius(dist), 1.2)
        xy = disc(rng, 2000, radius)
        back = undistort_normalized(distort_normalized(xy, dist), dist)
        assert not np.isnan(back).any()
        np.testing.assert_allclose(back, xy, rtol=0, atol=1e-9)


def test_undistort_agrees_with_opencv() -> None:
    dist = np.array(REALISTIC[14])
    xy_d = disc(np.random.default_rng(7), 200, 0.7)
    ours = undistort_normalized(xy_d, dist)
    criteria = (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 500, 1e-15)
    ref = undistort_points_iter(xy_d[:, None, :], np.eye(3), dist, criteria)[:, 0, :]
    np.testing.assert_allclose(ours, ref, rtol=0, atol=1e-9)


def test_undistort_strong_distortion_still_converges() -> None:
    # Close to where the mapping turns around OpenCV's fixed-point iteration stalls; Newton does not.
    dist = [-0.5, 0.0, 0.0, 0.0]
    xy = disc(np.random.default_rng(3), 500, 0.95 * math.sqrt(2.0 / 3.0))
    back = undistort_normalized(distort_normalized(xy, dist), dist)
    np.testing.assert_allclose(back, xy, rtol=0, atol=1e-9)


def test_undistort_beyond_monotonic_radius_is_nan() -> None:
    # A distorted radius larger than the maximum of r (1 - 0.5 r²) has no preimage at all.
    dist = [-0.5, 0.0, 0.0, 0.0]
    g_max = float(radial_g(np.array(dist), np.array(math.sqrt(2.0 / 3.0)))[0])
    out = undistort_normalized([[1.05 * g_max, 0.0], [0.3, 0.1]], dist)
    assert np.isnan(out[0]).all()
    assert np.isfinite(out[1]).all()


def test_undistort_rejects_bad_iterations() -> None:
    with pytest.raises(ValueError, match="iterations"):
        undistort_normalized([0.1, 0.1], REALISTIC[5], iterations=0)
