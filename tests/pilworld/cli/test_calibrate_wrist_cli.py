"""``pilworld calibrate handeye --camera <wrist camera>`` end to end on the simulated rig, through ``main``."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from calib.camera_model import CameraModel
from calib.rotations import pose_difference
from pilworld.cli.main import main
from pilworld.config.rig import RigConfig

ROOT = Path(__file__).resolve().parents[3]
SIM = ROOT / "configs" / "rig" / "sim_dual_ur5e.yaml"


@pytest.fixture(scope="module")
def calibrated(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, dict[str, Any]]:
    """One left-wrist run (7 poses at 448²), saved as a recorded folder, with a rig copy."""
    out = tmp_path_factory.mktemp("wrist")
    argv = ["calibrate", "handeye", "--rig", str(SIM), "--camera", "cam_left_wrist", "--out", str(out / "w.yaml")]
    argv += ["--poses", "7", "--resolution", "448", "--save", str(out / "rec"), "--write-rig", str(out / "rig.yaml")]
    assert main([*argv, "--json"]) == 0
    return out, json.loads((out / "w.json").read_text(encoding="utf-8"))


def test_wrist_handeye_writes_the_camera_model_and_report(calibrated: tuple[Path, dict[str, Any]]) -> None:
    out, report = calibrated
    model = CameraModel.from_yaml(out / "w.yaml")
    assert model.name == "cam_left_wrist" and (model.width, model.height) == (448, 448)
    design = RigConfig.load(SIM).wrist_camera_model("cam_left_wrist")
    dt, dr = pose_difference(model.T_cam_base, design.T_cam_base)  # T_cam_tcp
    assert dt <= 5e-3 and dr <= 0.5
    assert np.allclose(model.resized(128, 128).K, design.K)
    assert report["calibration"] == "eye_in_hand" and report["camera"] == "cam_left_wrist" and report["arm"] == "left"
    assert report["truth"]["translation_err_mm"] <= 5.0 and report["truth"]["rotation_err_deg"] <= 0.5
    assert report["uncertainty"]["sigma_translation_mm"] > 0.0
    assert np.allclose(report["T_cam_tcp"], model.T_cam_base)


def test_the_written_rig_points_at_the_calibration(calibrated: tuple[Path, dict[str, Any]]) -> None:
    out, _ = calibrated
    rig = RigConfig.load(out / "rig.yaml")
    assert rig.wrist_cameras["cam_left_wrist"].file == str(out / "w.yaml")
    model = rig.wrist_camera_model("cam_left_wrist")
    assert (model.width, model.height) == (128, 128)
    assert np.allclose(model.T_cam_base, CameraModel.from_yaml(out / "w.yaml").T_cam_base)
    assert rig.wrist_cameras["cam_right_wrist"].file is None


def test_wrist_handeye_from_the_recorded_folder(
    calibrated: tuple[Path, dict[str, Any]], tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    out, report = calibrated
    capsys.readouterr()
    argv = ["calibrate", "handeye", "--rig", str(SIM), "--camera", "cam_left_wrist", "--from", str(out / "rec")]
    assert main([*argv, "--out", str(tmp_path / "again.yaml")]) == 0
    text = capsys.readouterr().out
    assert "7 recorded views" in text and "vs the simulator's truth" in text
    assert "wrist_cameras: {cam_left_wrist: {file:" in text
    again = json.loads((tmp_path / "again.json").read_text(encoding="utf-8"))
    assert np.allclose(again["T_tcp_cam"], report["T_tcp_cam"], atol=1e-9)  # PNG is lossless


def test_unknown_camera_is_a_one_line_error(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    argv = ["calibrate", "handeye", "--rig", str(SIM), "--camera", "cam_top", "--out", str(tmp_path / "x.yaml")]
    assert main(argv) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1
    assert "cam_top" in err and "cam_high, cam_left_wrist, cam_right_wrist" in err


def test_wrong_arm_and_write_rig_for_the_head_are_errors(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    base = ["calibrate", "handeye", "--rig", str(SIM), "--out", str(tmp_path / "x.yaml")]
    assert main([*base, "--camera", "cam_left_wrist", "--arm", "right"]) == 2
    assert "carried by the left arm" in capsys.readouterr().err
    assert main([*base, "--write-rig", str(tmp_path / "r.yaml")]) == 2
    assert "--write-rig: only for a wrist camera" in capsys.readouterr().err
