"""Tests for calib.sweep: the synthetic eye-to-hand trials and the stability sweep."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

from calib.handeye import check_motion
from calib.rotations import pose_difference
from calib.sweep import (
    DEFAULT_VALUES,
    SweepConditions,
    available_methods,
    count_points,
    make_trial,
    opencv_methods_available,
    run_sweep,
    solve_trial,
    sweep_points,
)
from tests.calib.opencv_compat import require_hand_eye


def test_noise_free_trial_is_solved_exactly_by_every_method() -> None:
    trial = make_trial(SweepConditions(pixel_noise_px=0.0, fk_noise_deg=0.0), seed=3)
    assert trial.T_base_gripper.shape == (10, 4, 4) and trial.image_points.shape == (10, 24, 2)
    np.testing.assert_array_equal(trial.T_base_gripper, trial.T_base_gripper_true)
    # The model holds: every measured board pose is T_cam_base · G_i · T_gripper_board.
    for G, C in zip(trial.T_base_gripper, trial.T_cam_board, strict=True):
        dt, dr = pose_difference(trial.camera.T_cam_base @ G @ trial.T_gripper_board, C)
        assert dt < 1e-9 and dr < 1e-7
    for name, outcome in solve_trial(trial).items():
        assert outcome.refused is None, name
        assert outcome.trans_mm < 1e-5 and outcome.rot_deg < 1e-5, name


@pytest.mark.parametrize("span", [10.0, 40.0, 80.0])
def test_rotation_span_is_what_was_asked(span: float) -> None:
    trial = make_trial(SweepConditions(poses=6, rotation_span_deg=span, fk_noise_deg=0.0), seed=1)
    assert check_motion(trial.T_base_gripper_true).rotation_span_deg == pytest.approx(span, abs=1e-6)


def test_fk_noise_perturbs_the_gripper_poses_by_the_stated_amount() -> None:
    trial = make_trial(SweepConditions(poses=200, fk_noise_deg=0.1, rotation_span_deg=20.0), seed=0)
    pairs = zip(trial.T_base_gripper, trial.T_base_gripper_true, strict=True)
    diffs = np.array([pose_difference(a, b) for a, b in pairs])
    # σ per axis: 0.1° of rotation and 0.1° in radians × 0.5 m = 0.87 mm; the 3-D norms have RMS √3 σ.
    assert math.sqrt(np.mean(diffs[:, 1] ** 2)) == pytest.approx(math.sqrt(3) * 0.1, rel=0.15)
    assert math.sqrt(np.mean(diffs[:, 0] ** 2)) == pytest.approx(math.sqrt(3) * math.radians(0.1) * 0.5, rel=0.15)


def test_error_grows_with_pixel_noise_and_refinement_beats_closed_forms() -> None:
    result = run_sweep(6, values={"pixel_noise": (0.1, 1.0)}, methods=["shah", "refined"])
    shah, refined = result.axes["pixel_noise"]["shah"], result.axes["pixel_noise"]["refined"]
    assert shah[1].trans_mm_median > 2 * shah[0].trans_mm_median  # type: ignore[operator]
    assert shah[1].rot_deg_median > 2 * shah[0].rot_deg_median  # type: ignore[operator]
    assert refined[1].trans_mm_median < shah[1].trans_mm_median  # type: ignore[operator]
    assert all(s.refused == 0 and s.trials == 6 for s in shah + refined)


def test_tiny_rotation_span_is_refused_by_our_methods() -> None:
    methods = available_methods()
    result = run_sweep(3, values={"rotation_span": (2.0, 40.0)}, methods=methods)
    for name in ("park_martin", "shah", "refined"):
        tiny, good = result.axes["rotation_span"][name]
        assert tiny.refused == 3 and tiny.trans_mm_median is None and tiny.exceeds == 0
        assert tiny.refusal is not None and "rotation span too small" in tiny.refusal
        assert good.refused == 0 and good.trans_mm_median is not None
    require_hand_eye()
    # OpenCV's TSAI does not refuse: it returns the identity (1 m, ~170° off here).
    tsai = result.axes["rotation_span"]["opencv_tsai"][0]
    assert tsai.refused == 0 and tsai.exceeds == 3 and tsai.trans_mm_median > 100.0  # type: ignore[operator]


def test_result_is_json_ready_and_methods_follow_cv2() -> None:
    result = run_sweep(1, values={"poses": (3,), "fk_noise": (0.2,)})
    data = json.loads(json.dumps(result.to_dict(), allow_nan=False))
    assert set(data["axes"]) == {"poses", "fk_noise"}
    assert data["methods"][:3] == ["park_martin", "shah", "refined"]
    assert data["opencv_methods_available"] == opencv_methods_available()
    require_hand_eye()
    assert {"opencv_tsai", "opencv_daniilidis"} <= set(data["methods"])
    point = data["axes"]["poses"]["refined"][0]
    assert set(point) >= {"value", "trans_mm_median", "trans_mm_p90", "rot_deg_median", "rot_deg_p90", "refused"}
    assert point["value"] == 3 and data["defaults"]["poses"] == 10


def test_sweep_points_vary_one_axis_at_a_time() -> None:
    points = list(sweep_points(SweepConditions()))
    assert len(points) == count_points() == sum(len(v) for v in DEFAULT_VALUES.values())
    for axis, value, cond in points:
        changed = {k for k, v in vars(cond).items() if v != getattr(SweepConditions(), k)}
        assert changed <= {{"pixel_noise": "pixel_noise_px", "fk_noise": "fk_noise_deg", "poses": "poses",
                             "rotation_span": "rotation_span_deg"}[axis]}, (axis, value)  # fmt: skip


def test_bad_input_raises() -> None:
    with pytest.raises(ValueError, match="pixel_noise_px"):
        SweepConditions(pixel_noise_px=-1.0)
    with pytest.raises(ValueError, match="poses"):
        SweepConditions(poses=1)
    with pytest.raises(ValueError, match="rotation_span_deg"):
        SweepConditions(rotation_span_deg=170.0)
    with pytest.raises(ValueError, match="trials"):
        run_sweep(0)
    with pytest.raises(ValueError, match="unknown 'tilt'"):
        run_sweep(1, values={"tilt": (1.0,)})
    with pytest.raises(ValueError, match="unknown or unavailable"):
        solve_trial(make_trial(SweepConditions(), 0), ["opencv_magic"])
