"""``pilworld bench calibration``: the JSON figures, the sweep and its chart."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from calib.sweep import AXES, available_methods, run_sweep
from pilworld.bench.calibration import handeye_figures, plot_sweep
from pilworld.cli.main import main
from simrig.files import SIM_RIG as DEFAULT_RIG

HEADLINE = (
    "intrinsics_focal_rel_err",
    "intrinsics_focal_rel_err_percent",
    "intrinsics_pp_err_px",
    "intrinsics_rms_px",
    "intrinsics_ci95_coverage",
    "handeye_trans_err_mm",
    "handeye_rot_err_deg",
    "gripper_reproj_err_px",
)


@pytest.mark.slow  # a whole quick bench, ~20 s idle: keeps the default suite near its 15 min
def test_quick_json_has_every_figure_and_writes_the_chart(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    out = tmp_path / "chart"
    assert main(["bench", "calibration", "--quick", "--json", "--no-progress", "--out", str(out)]) == 0
    lines = capsys.readouterr().out.strip().splitlines()
    data = json.loads(lines[-1])
    assert data["bench"] == "calibration" and data["quick"] is True
    for key in HEADLINE:
        assert isinstance(data[key], float) and data[key] >= 0.0, key
    assert data["intrinsics_focal_rel_err_percent"] == pytest.approx(100 * data["intrinsics_focal_rel_err"])
    # Quick = 2 seeds: loose sanity bounds (the full 20-seed figures are in docs/calibration_bench.md).
    assert data["intrinsics_focal_rel_err"] < 0.01 and data["intrinsics_rms_px"] < 0.6
    assert data["handeye_source"] == "synthetic" and data["handeye_trans_err_mm"] < 5.0
    assert set(data["sweep"]) == set(AXES)
    assert data["opencv_methods_available"] == data["sweep_settings"]["opencv_methods_available"]
    for per_method in data["sweep"].values():
        assert list(per_method) == available_methods()
        for stats in per_method.values():
            for s in stats:
                assert {"value", "trans_mm_median", "trans_mm_p90", "rot_deg_median", "rot_deg_p90", "refused"} <= set(
                    s
                )
    # Tiny spans are refused by our closed forms, never silently answered.
    assert data["sweep"]["rotation_span"]["shah"][0]["refused"] == data["sweep_settings"]["trials"]
    chart = Path(data["chart"])
    assert chart == out / "calibration_sweep.png" and chart.stat().st_size > 10_000
    assert chart.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert any(line.startswith("chart: ") for line in lines) and data["seconds"]["total"] > 0


def test_bad_arguments_exit_2(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["bench", "calibration", "--trials", "0", "--json", "--no-progress"]) == 2
    assert "--trials" in capsys.readouterr().err
    with pytest.raises(ValueError, match="handeye-source"):
        handeye_figures("magic", trials=1, poses=5, rig_path=Path("x"), seed=0, progress=False)


def test_chart_of_a_sweep_with_refusals(tmp_path: Path) -> None:
    sweep = run_sweep(1, values={"rotation_span": (2.0, 40.0), "poses": (4, 10)}, methods=["shah", "refined"])
    path = plot_sweep(sweep.to_dict(), tmp_path / "sub" / "sweep.png")
    assert path.exists() and path.stat().st_size > 5_000


def test_headline_from_the_rendered_sim_rig_is_labelled() -> None:
    result = handeye_figures("sim", trials=1, poses=8, rig_path=DEFAULT_RIG, seed=0, progress=False)
    assert result["handeye_source"] == "sim_rendered" and result["handeye"]["poses"] == 8
    # Clean renders: well inside the 2 mm / 0.2°.
    assert result["handeye_trans_err_mm"] < 2.0 and result["handeye_rot_err_deg"] < 0.2
    assert result["handeye_synthetic"]["poses"] == 8 and result["handeye_synthetic"]["trials"] == 1
