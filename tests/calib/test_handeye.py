"""Tests for calib.handeye (closed forms, degeneracy), calib.handeye_refine and calib.handeye_opencv."""

from __future__ import annotations

import math
import re

import cv2
import numpy as np
import pytest

from calib.board import ChArUcoBoard
from calib.handeye import DegenerateMotionError, check_motion, solve_ax_xb
from calib.handeye_opencv import opencv_eye_to_hand
from calib.handeye_refine import refine_eye_to_hand, reprojection_residuals
from calib.handeye_solve import solve_eye_to_hand
from calib.rotations import pose_difference, rigid, rotation_exp, rotation_log
from calib.synthetic import random_board_pose
from pilworld.geometry import invert_transform
from tests.calib.opencv_compat import require_hand_eye

from .scenes import A4, TRUE_CAMERA, TRUE_DIST, TRUE_K

# The head camera high above the table looking down and forward (base/rig frame: z up), and the board
# held 12 cm off the gripper axis.
T_CAM_BASE = rigid(rotation_exp([2.2, 0.1, -0.3]), [0.05, 0.3, 1.1])
T_GRIPPER_BOARD = rigid(rotation_exp([0.1, -0.2, 0.3]), [-0.12, -0.08, 0.05])


def _scene(seed: int, n: int = 15, noise_px: float = 0.0) -> tuple[list, list, list, list]:
    """Gripper poses, PnP board poses, board points and pixels of ``n`` views of the A4 board in the gripper."""
    rng = np.random.default_rng(seed)
    board = ChArUcoBoard.from_yaml(A4)
    P = board.corner_points()
    G, C, objs, imgs = [], [], [], []
    for _ in range(n):
        T_cam_board = random_board_pose(board, TRUE_CAMERA, rng)  # a board pose the camera sees fully
        G.append(invert_transform(T_CAM_BASE) @ T_cam_board @ invert_transform(T_GRIPPER_BOARD))
        uv, _ = TRUE_CAMERA.with_pose(T_cam_board).project(P)
        uv = uv + rng.normal(0.0, noise_px, uv.shape)
        _, rvec, tvec = cv2.solvePnP(P, uv, TRUE_K, TRUE_DIST, flags=cv2.SOLVEPNP_IPPE)
        rvec, tvec = cv2.solvePnPRefineLM(P, uv, TRUE_K, TRUE_DIST, rvec, tvec)
        C.append(rigid(cv2.Rodrigues(rvec)[0], tvec))
        objs.append(P)
        imgs.append(uv)
    return G, C, objs, imgs


@pytest.mark.parametrize("method", ["park", "shah"])
def test_exact_poses_are_recovered(method: str) -> None:
    G, C, _, _ = _scene(0)
    result = solve_eye_to_hand(G, C, method=method)  # type: ignore[arg-type]
    dt, dr = pose_difference(result.T_cam_base, T_CAM_BASE)
    assert dt < 1e-3 and dr < 0.05  # the acceptance bound; in fact ~1e-12
    assert dt < 1e-8 and dr < 1e-6
    dt, dr = pose_difference(result.T_gripper_board, T_GRIPPER_BOARD)
    assert dt < 1e-8 and dr < 1e-6
    assert result.residual_rms_m < 1e-8 and result.motion.n_poses == 15
    assert result.motion.rotation_span_deg > 40.0 and result.motion.axis_spread > 0.3


def test_noisy_pixels_closed_form_then_refinement() -> None:
    errors = {"park": [], "shah": [], "refined": []}
    for seed in range(4):
        G, C, objs, imgs = _scene(seed, noise_px=0.3)
        for method in ("park", "shah"):
            result = solve_eye_to_hand(G, C, method=method)  # type: ignore[arg-type]
            errors[method].append(pose_difference(result.T_cam_base, T_CAM_BASE))
        refined = refine_eye_to_hand(result.T_cam_base, result.T_gripper_board, G, objs, imgs, TRUE_K, TRUE_DIST)
        assert refined.converged and refined.rms_px <= refined.initial_rms_px
        assert 0.3 < refined.rms_px < 0.5  # ≈ 0.3·√2: only the pixel noise is left
        errors["refined"].append(pose_difference(refined.T_cam_base, T_CAM_BASE))
    # Closed forms weigh every PnP pose alike (steep, far boards are poorly measured): a few mm. The pixel
    # refinement is well inside the 2 mm / 0.2° (measured: median ~0.2 mm, 0.02°).
    bounds = {"park": (5.0, 0.3), "shah": (5.0, 0.3), "refined": (1.0, 0.1)}
    for method, errs in errors.items():
        worst_mm = 1e3 * max(e[0] for e in errs)
        worst_deg = max(e[1] for e in errs)
        assert worst_mm < bounds[method][0] and worst_deg < bounds[method][1], (method, worst_mm, worst_deg)
    # The refinement uses the pixels directly and beats the algebraic closed forms.
    assert np.median([e[0] for e in errors["refined"]]) < np.median([e[0] for e in errors["shah"]])


def test_refinement_is_robust_to_a_few_bad_corners() -> None:
    G, C, objs, imgs = _scene(1, noise_px=0.3)
    imgs = [im.copy() for im in imgs]
    imgs[3][:3] += 25.0  # three grossly wrong corners (a mis-detection)
    start = solve_eye_to_hand(G, C, method="shah")
    refined = refine_eye_to_hand(start.T_cam_base, start.T_gripper_board, G, objs, imgs, TRUE_K, TRUE_DIST)
    dt, dr = pose_difference(refined.T_cam_base, T_CAM_BASE)
    assert dt < 2e-3 and dr < 0.2
    r = reprojection_residuals(refined.T_cam_base, refined.T_gripper_board, G, objs, imgs, TRUE_K, TRUE_DIST)
    assert np.median(np.linalg.norm(r, axis=1)) < 0.6


def _rotations_about(axis: np.ndarray, angles_deg: list[float], seed: int = 0) -> list[np.ndarray]:
    rng = np.random.default_rng(seed)
    a = axis / np.linalg.norm(axis)
    return [rigid(rotation_exp(a * math.radians(d)), rng.uniform(-0.3, 0.3, 3)) for d in angles_deg]


def _camera_poses(G: list[np.ndarray]) -> list[np.ndarray]:
    return [T_CAM_BASE @ g @ T_GRIPPER_BOARD for g in G]


@pytest.mark.parametrize("method", ["park", "shah"])
def test_degenerate_motion_raises(method: str) -> None:
    rng = np.random.default_rng(3)
    axes = rng.normal(size=(10, 3))
    # Each pose within 2.4° of the first orientation: no two differ by more than 4.8° (<= 5°).
    small = [rigid(rotation_exp(a / np.linalg.norm(a) * math.radians(2.4)), rng.uniform(-0.3, 0.3, 3)) for a in axes]
    with pytest.raises(DegenerateMotionError, match=r"rotation span too small: .* at most [0-5]\.\d\d°"):
        solve_eye_to_hand(small, _camera_poses(small), method=method)  # type: ignore[arg-type]
    one_axis = _rotations_about(np.array([0.2, -0.5, 1.0]), [-40, -25, -10, 0, 15, 30, 45])
    with pytest.raises(DegenerateMotionError, match="rotations about a single axis") as info:
        solve_eye_to_hand(one_axis, _camera_poses(one_axis), method=method)  # type: ignore[arg-type]
    named = re.search(r"all close to \[(\S+), (\S+), (\S+)\]", str(info.value))
    assert named is not None  # the message names the axis: (0.2, -0.5, 1) normalised, either sign
    axis = np.array([0.2, -0.5, 1.0]) / np.linalg.norm([0.2, -0.5, 1.0])
    assert abs(float(np.dot([float(v) for v in named.groups()], axis))) > 0.999
    two = _scene(0, n=15)[0][:2]
    with pytest.raises(DegenerateMotionError, match="too few poses: got 2"):
        solve_eye_to_hand(two, _camera_poses(two), method=method)  # type: ignore[arg-type]
    assert issubclass(DegenerateMotionError, ValueError)


def test_degeneracy_thresholds_are_configurable_and_reported() -> None:
    G = _scene(0, n=6)[0]
    report = check_motion(G)
    assert report.n_poses == 6 and report.rotation_span_deg > 20.0
    with pytest.raises(DegenerateMotionError, match="min_rotation_span_deg = 180"):
        check_motion(G, min_rotation_span_deg=180.0)
    # Rotations about x and about y only: all axes in one plane, yet well-posed (needs 2 axes, not 3).
    planar = _rotations_about(np.array([1.0, 0, 0]), [0, 30, -30]) + _rotations_about(np.array([0, 1.0, 0]), [30, -30])
    assert check_motion(planar).axis_spread > 0.3
    result = solve_eye_to_hand(planar, _camera_poses(planar))
    assert pose_difference(result.T_cam_base, T_CAM_BASE)[0] < 1e-8


def test_input_errors() -> None:
    G, C, _, _ = _scene(0, n=5)
    with pytest.raises(ValueError, match="pair up one to one, got 5 and 4"):
        solve_eye_to_hand(G, C[:4])
    bad = [g.copy() for g in G]
    bad[2][:3, :3] *= 1.01
    with pytest.raises(ValueError, match=r"T_base_gripper\[2\] is not a rigid transform"):
        solve_eye_to_hand(bad, C)
    with pytest.raises(ValueError, match="method"):
        solve_eye_to_hand(G, C, method="tsai")  # type: ignore[arg-type]
    with pytest.raises(DegenerateMotionError):
        solve_ax_xb([np.eye(4)] * 3, [np.eye(4)] * 3)


def test_opencv_reference_is_installed() -> None:
    require_hand_eye()


def test_opencv_cross_check_agrees() -> None:
    require_hand_eye()
    G, C, _, _ = _scene(2)
    ours = solve_eye_to_hand(G, C)
    estimates = opencv_eye_to_hand(G, C, reference_T_cam_base=ours.T_cam_base)
    assert {"TSAI", "PARK", "HORAUD", "ANDREFF", "DANIILIDIS", "SHAH", "LI"} <= set(estimates)
    for est in estimates.values():  # noise-free: every method lands on the same answer
        assert est.translation_diff_m < 1e-6 and est.rotation_diff_deg < 1e-4, est.method
    G, C, _, _ = _scene(2, noise_px=0.3)
    ours = solve_eye_to_hand(G, C)
    for est in opencv_eye_to_hand(G, C, reference_T_cam_base=ours.T_cam_base).values():
        # ANDREFF and LI solve rotation and translation jointly and are the noisiest (~3-5 mm here).
        assert est.translation_diff_m < 1e-2 and est.rotation_diff_deg < 0.3, est.method


@pytest.mark.parametrize("angle", [0.0, 1e-9, 0.3, 2.0, math.pi - 1e-6, math.pi])
def test_rotation_log_exp_round_trip(angle: float) -> None:
    axis = np.array([0.3, -0.4, 0.866])
    w = axis / np.linalg.norm(axis) * angle
    R = rotation_exp(w)
    np.testing.assert_allclose(R, cv2.Rodrigues(w)[0], atol=1e-12)
    np.testing.assert_allclose(rotation_exp(rotation_log(R)), R, atol=1e-9)
