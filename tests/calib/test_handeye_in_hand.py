"""Eye-in-hand calibration (wrist camera, board fixed on the table): closed forms, refinement, refusals."""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest

from calib.handeye import DegenerateMotionError, check_eye_in_hand_motion
from calib.handeye_refine import eye_in_hand_residuals, refine_eye_in_hand
from calib.handeye_solve import solve_eye_in_hand
from calib.rotations import pose_difference, rigid, rotation_exp
from calib.sweep import (
    IN_HAND_DEFAULTS,
    IN_HAND_VALUES,
    T_BASE_BOARD,
    T_TCP_CAM,
    make_in_hand_trial,
    run_in_hand_sweep,
    solve_in_hand_trial,
)
from pilworld.geometry import invert_transform

EXACT = replace(IN_HAND_DEFAULTS, pixel_noise_px=0.0, fk_noise_deg=0.0)


@pytest.mark.parametrize("method", ["park", "shah"])
def test_closed_forms_recover_exact_mount_and_board(method: str) -> None:
    trial = make_in_hand_trial(EXACT, seed=3)
    result = solve_eye_in_hand(trial.T_base_tcp, trial.T_cam_board, method=method)  # type: ignore[arg-type]
    dt, dr = pose_difference(result.T_tcp_cam, T_TCP_CAM)
    assert dt < 1e-9 and dr < 1e-7
    dt, dr = pose_difference(result.T_base_board, T_BASE_BOARD)
    assert dt < 1e-9 and dr < 1e-7
    assert result.residual_rms_m < 1e-9
    assert np.allclose(result.T_cam_tcp @ result.T_tcp_cam, np.eye(4))


def test_the_model_holds_for_the_synthetic_trial() -> None:
    trial = make_in_hand_trial(EXACT, seed=0)
    for g, c in zip(trial.T_base_tcp_true, trial.T_cam_board, strict=True):
        assert np.allclose(g @ T_TCP_CAM @ c, T_BASE_BOARD, atol=1e-9)
    r = eye_in_hand_residuals(
        T_TCP_CAM, T_BASE_BOARD, trial.T_base_tcp, [trial.board_points] * 10, list(trial.image_points), trial.camera.K,
        trial.camera.dist,
    )  # fmt: skip
    assert np.abs(r).max() < 1e-6


def test_a_wrong_mount_is_not_recovered() -> None:
    """The solver uses the camera poses: feeding another trial's camera poses must give a wrong answer."""
    a, b = make_in_hand_trial(EXACT, seed=1), make_in_hand_trial(EXACT, seed=2)
    result = solve_eye_in_hand(a.T_base_tcp, b.T_cam_board, method="shah")
    assert pose_difference(result.T_tcp_cam, T_TCP_CAM)[0] > 0.01


def test_refinement_beats_closed_form_under_noise_and_reports_uncertainty() -> None:
    errors_closed, errors_refined, sigmas = [], [], []
    for seed in range(5):
        trial = make_in_hand_trial(replace(IN_HAND_DEFAULTS, pixel_noise_px=0.5, fk_noise_deg=0.0, poses=15), seed)
        start = solve_eye_in_hand(trial.T_base_tcp, trial.T_cam_board)
        refined = refine_eye_in_hand(
            start.T_tcp_cam, start.T_base_board, trial.T_base_tcp, [trial.board_points] * 15,
            list(trial.image_points), trial.camera.K, trial.camera.dist,
        )  # fmt: skip
        errors_closed.append(pose_difference(start.T_tcp_cam, T_TCP_CAM)[0])
        errors_refined.append(pose_difference(refined.T_tcp_cam, T_TCP_CAM)[0])
        sigmas.append(refined.sigma_translation_mm)
        assert refined.rms_px < refined.initial_rms_px
        assert 0.3 < refined.rms_px < 0.8  # 0.5 px per coordinate ≈ 0.7 px per corner
        u = refined.uncertainty()
        assert u["sigma_translation_mm"] > 0.0 and u["sigma_rotation_deg"] > 0.0
    assert np.median(errors_refined) < np.median(errors_closed)
    assert max(errors_refined) < 2e-3
    # The reported σ is of the right size: the errors are within a few σ.
    for err, sigma in zip(errors_refined, sigmas, strict=True):
        assert err * 1e3 < 5.0 * float(np.linalg.norm(sigma))


def test_noise_robustness_within_acceptance() -> None:
    """Default noise (0.3 px, FK 0.02°), 20 poses: the refined mount within 2 mm and 0.2° on every seed."""
    for seed in range(5):
        trial = make_in_hand_trial(replace(IN_HAND_DEFAULTS, poses=20), 100 + seed)
        out = solve_in_hand_trial(trial)
        assert out["refined"].refused is None
        assert out["refined"].trans_mm < 2.0 and out["refined"].rot_deg < 0.2


def _tcp_poses(rotations: list[np.ndarray], shifts: list[list[float]]) -> list[np.ndarray]:
    base = rigid(np.diag([1.0, -1.0, -1.0]), [0.4, 0.1, 0.4])
    return [base @ rigid(R, t) for R, t in zip(rotations, shifts, strict=True)]


def test_pure_translation_is_refused_naming_the_motion_to_add() -> None:
    G = _tcp_poses([np.eye(3)] * 6, [[0.05 * k, 0.02 * (k % 2), 0.01 * k] for k in range(6)])
    C = [invert_transform(T_TCP_CAM) @ invert_transform(g) @ T_BASE_BOARD for g in G]
    with pytest.raises(DegenerateMotionError, match="pure translation") as info:
        solve_eye_in_hand(G, C)
    assert "add rotations about two different axes" in str(info.value)
    with pytest.raises(DegenerateMotionError, match="pure translation"):
        check_eye_in_hand_motion(G)


def test_single_rotation_axis_is_refused_naming_the_axis_and_a_second_one() -> None:
    axis = np.array([1.0, 0.0, 0.0])
    G = _tcp_poses(
        [rotation_exp(axis * math.radians(a)) for a in (-30, -15, 0, 10, 25)],
        [[0.0, 0.01 * k, 0.0] for k in range(5)],
    )
    C = [invert_transform(T_TCP_CAM) @ invert_transform(g) @ T_BASE_BOARD for g in G]
    with pytest.raises(DegenerateMotionError, match="rotations about a single axis") as info:
        solve_eye_in_hand(G, C, method="park")
    text = str(info.value)
    assert "add rotations about a second axis" in text
    assert "[1.0, 0.0, 0.0]" in text  # the axis, in the TCP frame


def test_too_few_poses_is_refused() -> None:
    trial = make_in_hand_trial(EXACT, seed=0)
    with pytest.raises(DegenerateMotionError, match=r"too few poses.*add rotations"):
        solve_eye_in_hand(trial.T_base_tcp[:2], trial.T_cam_board[:2])


def test_mismatched_inputs_and_methods() -> None:
    trial = make_in_hand_trial(EXACT, seed=0)
    with pytest.raises(ValueError, match="pair up"):
        solve_eye_in_hand(trial.T_base_tcp, trial.T_cam_board[:-1])
    with pytest.raises(ValueError, match="method"):
        solve_eye_in_hand(trial.T_base_tcp, trial.T_cam_board, method="tsai")  # type: ignore[arg-type]


def test_in_hand_sweep_refuses_small_spans_and_is_accurate_at_defaults() -> None:
    result = run_in_hand_sweep(2, values={"rotation_span": (2.0, 40.0)})
    stats = result.to_dict()["axes"]["rotation_span"]["refined"]
    assert stats[0]["refused"] == 2 and "pure translation" in stats[0]["refusal"]
    assert stats[1]["refused"] == 0 and stats[1]["trans_mm_median"] < 2.0
    assert set(IN_HAND_VALUES) == {"pixel_noise", "fk_noise", "poses", "rotation_span"}
