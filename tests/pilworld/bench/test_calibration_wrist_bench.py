"""The wrist-camera part of ``pilworld bench calibration``: figures, refusals and the eye-in-hand sweep."""

from __future__ import annotations

from pathlib import Path

import pytest

from pilworld.bench.calibration import run_calibration_bench, wrist_degeneracy_checks, wrist_figures


@pytest.mark.slow  # a whole quick bench, ~20 s idle: keeps the default suite near its 15 min
def test_quick_bench_reports_the_wrist_cameras(tmp_path: Path) -> None:
    r = run_calibration_bench(quick=True, progress=False, out_dir=tmp_path)
    assert r["wrist_source"] == "synthetic"
    assert set(r["wrist"]["cameras"]) == {"cam_left_wrist", "cam_right_wrist"}
    assert r["wrist_trans_err_mm_max"] == max(e["trans_err_mm_max"] for e in r["wrist"]["cameras"].values())
    assert r["wrist_degenerate"]["all_refused_with_advice"] is True
    assert set(r["wrist_sweep"]) == {"pixel_noise", "fk_noise", "poses", "rotation_span"}
    assert (
        r["wrist_sweep"]["rotation_span"]["refined"][0]["refused"]
        == r["wrist_sweep"]["rotation_span"]["refined"][0]["trials"]
    )
    assert r["seconds"]["wrist"] > 0.0
    # The existing keys are still there.
    assert {"handeye_trans_err_mm", "sweep", "intrinsics_focal_rel_err", "chart"} <= set(r)


def test_degeneracy_messages_name_the_motion_to_add() -> None:
    checks = wrist_degeneracy_checks()
    assert "pure translation" in checks["pure_translation"]["message"]
    assert "add rotations about two different axes" in checks["pure_translation"]["message"]
    assert "add rotations about a second axis" in checks["single_axis"]["message"]


def test_sim_wrist_figures_on_one_reduced_seed() -> None:
    r = wrist_figures("sim", seeds=1, poses=8, resolution=512, cameras=("cam_left_wrist",), progress=False)
    entry = r["wrist"]["cameras"]["cam_left_wrist"]
    assert r["wrist_source"] == "sim_rendered"
    assert entry["trans_err_mm_max"] <= 5.0 and entry["rot_err_deg_max"] <= 0.5
    assert entry["sigma_translation_mm_max"] > 0.0 and entry["board_reproj_err_px_max"] < 1.0
    with pytest.raises(ValueError, match="wrist source"):
        wrist_figures("auto")
