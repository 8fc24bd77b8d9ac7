"""Rigid-transform helpers: rotations, RPY, pose/matrix conversion, inversion, point transforms."""

from __future__ import annotations

import math

import numpy as np
import pytest

from pilworld.geometry import (
    invert_transform,
    is_rigid_transform,
    matrix_to_pose,
    matrix_to_rpy,
    pose_to_matrix,
    rot_x,
    rot_y,
    rot_z,
    rpy_to_matrix,
    transform_points,
)


def _random_poses(rng: np.random.Generator, n: int) -> np.ndarray:
    xyz = rng.uniform(-2, 2, size=(n, 3))
    rpy = rng.uniform(-math.pi, math.pi, size=(n, 3))
    return pose_to_matrix(xyz, rpy)


# --- elementary rotations -------------------------------------------------------------------------


def test_elementary_rotations_match_textbook_formulas() -> None:
    a = 0.3
    c, s = math.cos(a), math.sin(a)
    np.testing.assert_allclose(rot_x(a), [[1.0, 0.0, 0.0], [0.0, c, -s], [0.0, s, c]], atol=1e-15)
    np.testing.assert_allclose(rot_y(a), [[c, 0.0, s], [0.0, 1.0, 0.0], [-s, 0.0, c]], atol=1e-15)
    np.testing.assert_allclose(rot_z(a), [[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]], atol=1e-15)
    # Right-handedness: a quarter turn maps the next axis in the x->y->z cycle onto the one after.
    e = np.eye(3)
    np.testing.assert_allclose(rot_x(math.pi / 2) @ e[1], e[2], atol=1e-15)
    np.testing.assert_allclose(rot_y(math.pi / 2) @ e[2], e[0], atol=1e-15)
    np.testing.assert_allclose(rot_z(math.pi / 2) @ e[0], e[1], atol=1e-15)


@pytest.mark.parametrize("shape", [(), (5,), (2, 3)])
def test_elementary_rotations_batch(shape: tuple[int, ...]) -> None:
    a = np.random.default_rng(0).uniform(-4, 4, size=shape)
    for rot in (rot_x, rot_y, rot_z):
        R = rot(a)
        assert R.shape == (*shape, 3, 3)
        assert R.dtype == np.float64
        for idx in np.ndindex(*shape):
            np.testing.assert_array_equal(R[idx], rot(float(a[idx])))


# --- roll / pitch / yaw ---------------------------------------------------------------------------


def test_rpy_is_z_y_x_product() -> None:
    rpy = np.random.default_rng(1).uniform(-math.pi, math.pi, size=(20, 3))
    expected = rot_z(rpy[:, 2]) @ rot_y(rpy[:, 1]) @ rot_x(rpy[:, 0])
    np.testing.assert_allclose(rpy_to_matrix(rpy), expected, rtol=0, atol=1e-15)
    # Pure yaw of 90 deg sends x to y.
    np.testing.assert_allclose(rpy_to_matrix([0, 0, math.pi / 2]) @ [1, 0, 0], [0, 1, 0], atol=1e-15)


def test_rpy_round_trip() -> None:
    rng = np.random.default_rng(2)
    n = 2000
    rpy = np.stack(
        [
            rng.uniform(-math.pi, math.pi, n),
            rng.uniform(-math.pi / 2 + 1e-6, math.pi / 2 - 1e-6, n),
            rng.uniform(-math.pi, math.pi, n),
        ],
        axis=-1,
    )
    R = rpy_to_matrix(rpy)
    back = matrix_to_rpy(R)
    assert back.shape == (n, 3)
    np.testing.assert_allclose(back, rpy, rtol=0, atol=1e-9)
    np.testing.assert_allclose(rpy_to_matrix(back), R, rtol=0, atol=1e-12)


@pytest.mark.parametrize("pitch", [math.pi / 2, -math.pi / 2])
def test_matrix_to_rpy_gimbal_lock_is_deterministic(pitch: float) -> None:
    R = rpy_to_matrix([[0.4, pitch, -1.1], [-0.2, pitch, 2.5]])
    rpy = matrix_to_rpy(R)
    np.testing.assert_array_equal(rpy[:, 0], 0.0)  # roll is attributed to yaw
    np.testing.assert_allclose(rpy[:, 1], pitch, atol=1e-12)
    np.testing.assert_allclose(rpy_to_matrix(rpy), R, rtol=0, atol=1e-12)


def test_matrix_to_rpy_identity() -> None:
    np.testing.assert_array_equal(matrix_to_rpy(np.eye(3)), [0.0, 0.0, 0.0])


# --- poses ----------------------------------------------------------------------------------------


def test_pose_round_trip_batched() -> None:
    rng = np.random.default_rng(3)
    xyz = rng.uniform(-1, 1, size=(4, 5, 3))
    rpy = rng.uniform(-1.5, 1.5, size=(4, 5, 3))
    T = pose_to_matrix(xyz, rpy)
    assert T.shape == (4, 5, 4, 4)
    assert is_rigid_transform(T)
    xyz2, rpy2 = matrix_to_pose(T)
    np.testing.assert_allclose(xyz2, xyz, rtol=0, atol=1e-15)
    np.testing.assert_allclose(rpy2, rpy, rtol=0, atol=1e-12)


def test_pose_to_matrix_broadcasts_translation_and_rotation() -> None:
    T = pose_to_matrix([0.1, 0.2, 0.3], np.zeros((3, 3)))
    assert T.shape == (3, 4, 4)
    np.testing.assert_array_equal(T[:, :3, 3], np.broadcast_to([0.1, 0.2, 0.3], (3, 3)))


def test_invert_transform() -> None:
    T = _random_poses(np.random.default_rng(4), 100)
    T_inv = invert_transform(T)
    np.testing.assert_allclose(T_inv @ T, np.broadcast_to(np.eye(4), T.shape), rtol=0, atol=1e-12)
    np.testing.assert_allclose(T @ T_inv, np.broadcast_to(np.eye(4), T.shape), rtol=0, atol=1e-12)
    np.testing.assert_allclose(T_inv, np.linalg.inv(T), rtol=0, atol=1e-12)
    np.testing.assert_array_equal(T_inv[:, 3], np.broadcast_to([0.0, 0.0, 0.0, 1.0], (100, 4)))
    np.testing.assert_allclose(invert_transform(T[0]) @ T[0], np.eye(4), rtol=0, atol=1e-12)


# --- points ---------------------------------------------------------------------------------------


def test_transform_points_batching() -> None:
    rng = np.random.default_rng(5)
    T = _random_poses(rng, 4)
    pts = rng.uniform(-1, 1, size=(7, 3))

    def homogeneous(T1: np.ndarray, p: np.ndarray) -> np.ndarray:
        return np.asarray(T1 @ np.append(p, 1.0), dtype=np.float64)[:3]

    single = transform_points(T[0], pts)  # one transform, a cloud
    assert single.shape == (7, 3)
    for j in range(7):
        np.testing.assert_allclose(single[j], homogeneous(T[0], pts[j]), atol=1e-14)

    pairwise = transform_points(T, pts[:4])  # (B, 4, 4) with (B, 3)
    assert pairwise.shape == (4, 3)
    for i in range(4):
        np.testing.assert_allclose(pairwise[i], homogeneous(T[i], pts[i]), atol=1e-14)

    outer = transform_points(T[:, None], pts)  # (B, 1, 4, 4) with (N, 3) -> (B, N, 3)
    assert outer.shape == (4, 7, 3)
    for i in range(4):
        np.testing.assert_allclose(outer[i], transform_points(T[i], pts), atol=1e-15)

    np.testing.assert_allclose(transform_points(np.eye(4), [1.0, 2.0, 3.0]), [1.0, 2.0, 3.0])


def test_transform_points_round_trip_with_inverse() -> None:
    rng = np.random.default_rng(6)
    T = _random_poses(rng, 10)
    pts = rng.uniform(-1, 1, size=(10, 3))
    np.testing.assert_allclose(transform_points(invert_transform(T), transform_points(T, pts)), pts, atol=1e-12)


# --- rigidity -------------------------------------------------------------------------------------


def test_is_rigid_transform() -> None:
    T = _random_poses(np.random.default_rng(7), 5)
    assert is_rigid_transform(T)
    assert is_rigid_transform(np.eye(4))
    assert not is_rigid_transform(np.diag([1.0, 1.0, 1.01, 1.0]))  # scaling
    assert not is_rigid_transform(np.diag([1.0, 1.0, -1.0, 1.0]))  # reflection, det = -1
    bad_row = np.eye(4)
    bad_row[3, 0] = 0.5
    assert not is_rigid_transform(bad_row)
    nan = np.eye(4)
    nan[0, 3] = math.nan
    assert not is_rigid_transform(nan)
    assert is_rigid_transform(np.diag([1.0, 1.0, 1.0 + 1e-8, 1.0]))  # within the default atol
    assert not is_rigid_transform(np.diag([1.0, 1.0, 1.0 + 1e-8, 1.0]), atol=1e-10)


# --- validation -----------------------------------------------------------------------------------


@pytest.mark.parametrize(
    ("call", "match"),
    [
        (lambda: rpy_to_matrix([0.0, 1.0]), r"rpy must have shape \(\.\.\., 3\); got shape \(2,\)"),
        (lambda: matrix_to_rpy(np.eye(4)), r"R must have shape \(\.\.\., 3, 3\); got shape \(4, 4\)"),
        (lambda: pose_to_matrix([0.0, 0.0], [0.0, 0.0, 0.0]), r"xyz must have shape \(\.\.\., 3\)"),
        (
            lambda: pose_to_matrix(np.zeros((2, 3)), np.zeros((3, 3))),
            "xyz and rpy batch shapes must broadcast",
        ),
        (lambda: invert_transform(np.eye(3)), r"T must have shape \(\.\.\., 4, 4\); got shape \(3, 3\)"),
        (lambda: transform_points(np.eye(4), np.zeros((5, 4))), r"points must have shape \(\.\.\., 3\)"),
        (lambda: transform_points(np.zeros((2, 4, 4)), np.zeros((3, 3))), "must broadcast"),
        (lambda: is_rigid_transform(np.eye(3)), r"T must have shape \(\.\.\., 4, 4\)"),
        (lambda: is_rigid_transform(np.eye(4), atol=-1.0), "atol must be a finite non-negative"),
        (lambda: rot_x("abc"), "a must be a real-valued array-like"),
        (lambda: rot_z([0.0, math.nan]), r"a must contain only finite values; got nan at index \(1,\)"),
        (lambda: pose_to_matrix([0.0, math.inf, 0.0], [0.0, 0.0, 0.0]), "xyz must contain only finite"),
        (lambda: transform_points(np.eye(4), [[math.nan, 0.0, 0.0]]), "points must contain only finite"),
    ],
)
def test_invalid_input_raises_value_error(call: object, match: str) -> None:
    assert callable(call)
    with pytest.raises(ValueError, match=match):
        call()
