"""metrics.json read tolerantly: values, intervals, settings and per-frame curves in several layouts."""

from __future__ import annotations

import pytest

from pilworld.report.metrics_view import fmt, fmt_with_ci, interval, scalar, settings_points, single_step_curves


@pytest.mark.parametrize(
    ("value", "expected"),
    [(0.5, 0.5), (1, 1.0), ({"r": 0.9, "p": 0.01}, 0.9), ({"value": 0.25}, 0.25), (None, None), (True, None),
     ("0.5", None), (float("nan"), None), ({"p": 0.1}, None)],
)  # fmt: skip
def test_scalar(value: object, expected: float | None) -> None:
    assert scalar(value) == expected


def test_intervals_and_formatting() -> None:
    assert interval([0.1, 0.9]) == (0.1, 0.9)
    assert interval({"low": 0.2, "high": 0.8}) == (0.2, 0.8)
    assert interval({"lo": 0.2}) is None and interval("x") is None
    entry = {"sr_real": 0.5, "hfr": {"value": 0.8, "ci95": [0.7, 0.9]}, "ci95": {"sr_real": [0.25, 0.75]}}
    assert fmt_with_ci(entry, "sr_real") == ("0.50", "[0.25, 0.75]")
    assert fmt_with_ci(entry, "hfr") == ("0.80", "[0.70, 0.90]")
    assert fmt_with_ci(entry, "mmrv") == ("—", "")
    assert fmt(None) == "—" and fmt(0.12345) == "0.123"


def test_settings_skip_incomplete_entries() -> None:
    metrics = {
        "settings": [
            {"task": "t", "checkpoint": "a", "sr_real": 0.2, "sr_imag": 0.3, "n": 5},
            {"task": "t", "checkpoint": "b", "sr_real": 0.2},
            "junk",
        ]
    }
    assert settings_points(metrics) == [("t", "a", 0.2, 0.3, 5)]
    assert settings_points({"settings": {"not": "a list"}}) == []


@pytest.mark.parametrize(
    "single_step",
    [
        {"per_view": {"cam_high": {"psnr": [30, 29], "ssim": [0.9, 0.8]}, "cam_left_wrist": {"psnr": [28, 27]}}},
        {"psnr": {"cam_high": [30, 29], "cam_left_wrist": [28, 27]}, "ssim": {"cam_high": [0.9, 0.8]}},
        {"cam_high": [{"psnr": 30, "ssim": 0.9}, {"psnr": 29, "ssim": 0.8}], "cam_left_wrist": [{"psnr": 28},
                                                                                               {"psnr": 27}]},
    ],
)  # fmt: skip
def test_curves_from_any_nesting(single_step: object) -> None:
    curves = single_step_curves(single_step)
    assert curves["psnr"] == {"cam_high": [30.0, 29.0], "cam_left_wrist": [28.0, 27.0]}
    assert curves["ssim"] == {"cam_high": [0.9, 0.8]}


def test_pooled_curves_and_nothing_usable() -> None:
    assert single_step_curves({"per_frame": {"psnr": [30.0, None]}, "psnr": 29.5}) == {
        "psnr": {"all views": [30.0, None]}
    }
    assert single_step_curves(None) == {}
    assert single_step_curves({"per_frame": {"lpips": [0.1]}, "psnr": ["a"]}) == {}
