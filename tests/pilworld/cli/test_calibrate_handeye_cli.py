"""``pilworld calibrate handeye|check`` end to end on the simulated rig, through ``main``."""

from __future__ import annotations

import json
import shutil
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
    """One both-arm run (5 poses per arm at 512²), saved as a recorded folder: the other tests reuse it."""
    out = tmp_path_factory.mktemp("handeye")
    argv = ["calibrate", "handeye", "--rig", str(SIM), "--arm", "both", "--out", str(out / "cam.yaml")]
    argv += ["--poses", "5", "--resolution", "512", "--save", str(out / "rec"), "--json"]
    assert main(argv) == 0
    return out, json.loads((out / "cam.json").read_text(encoding="utf-8"))


def test_handeye_on_the_simulated_rig_writes_a_loadable_camera(
    calibrated: tuple[Path, dict[str, Any]],
) -> None:
    out, report = calibrated
    camera = CameraModel.from_yaml(out / "cam.yaml")
    assert (camera.width, camera.height) == (512, 512) and camera.name == "cam_high"
    truth = RigConfig.load(SIM).head_camera_model
    dt, dr = pose_difference(camera.T_cam_base, truth.T_cam_base)
    assert dt <= 0.002 and dr <= 0.2
    assert np.allclose(camera.resized(128, 128).K, truth.K)
    assert report["format"] == "pilworld.handeye_report/v1" and report["arm"] == "both"
    assert report["poses"] == 10 and report["rotation_span_deg"] >= 40.0
    assert set(report["arms"]) == {"left", "right"}
    disagreement = report["combined"]["disagreement"]
    assert 0.0 < disagreement["translation_mm"] <= 2.0 and disagreement["rotation_deg"] <= 0.2
    assert report["truth"]["translation_err_mm"] <= 2.0 and report["truth"]["gripper_reproj_err_px"] <= 1.0
    assert np.allclose(report["T_cam_base"], camera.T_cam_base)
    assert sorted(p.name for p in (out / "rec").iterdir())[-3:] == ["009.png", "camera.yaml", "poses.json"]


def test_handeye_from_a_recorded_folder(
    calibrated: tuple[Path, dict[str, Any]], tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    out, report = calibrated
    capsys.readouterr()
    argv = ["calibrate", "handeye", "--rig", str(SIM), "--arm", "left", "--from", str(out / "rec")]
    assert main([*argv, "--out", str(tmp_path / "left.yaml"), "--report", str(tmp_path / "r.json")]) == 0
    text = capsys.readouterr().out
    assert "10 recorded views" in text and "left arm: 5 poses" in text and "vs the simulator's truth" in text
    offline = json.loads((tmp_path / "r.json").read_text(encoding="utf-8"))
    assert offline["source"] == str(out / "rec") and set(offline["arms"]) == {"left"}
    # The same images and states give the same left-arm answer as the live run.
    assert np.allclose(offline["arms"]["left"]["T_cam_base"], report["arms"]["left"]["T_cam_base"], atol=1e-12)
    assert CameraModel.from_yaml(tmp_path / "left.yaml").T_cam_base == pytest.approx(np.asarray(offline["T_cam_base"]))


def test_handeye_errors_name_the_cause(
    calibrated: tuple[Path, dict[str, Any]], tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    out, _ = calibrated
    base = ["calibrate", "handeye", "--rig", str(SIM), "--out", str(tmp_path / "c.yaml")]
    capsys.readouterr()
    assert main([*base, "--arm", "left", "--poses", "2", "--resolution", "256"]) == 2
    err = capsys.readouterr().err
    assert "pilworld: error: hand-eye: degenerate motion: left arm, planned board poses: too few poses: got 2" in err
    assert not (tmp_path / "c.yaml").exists()  # nothing written for a refused calibration
    shutil.copytree(out / "rec", tmp_path / "rec")
    (tmp_path / "rec" / "camera.yaml").unlink()
    assert main([*base, "--from", str(tmp_path / "rec")]) == 2
    assert "--camera-model: needed" in capsys.readouterr().err
    assert main([*base, "--from", str(tmp_path / "missing")]) == 2
    assert "recording folder not found" in capsys.readouterr().err
    rec = json.loads((tmp_path / "rec" / "poses.json").read_text(encoding="utf-8"))
    rec["views"] = [v for v in rec["views"] if v["arm"] == "left"]
    (tmp_path / "rec" / "poses.json").write_text(json.dumps(rec), encoding="utf-8")
    cam = str(out / "rec" / "camera.yaml")
    assert main([*base, "--from", str(tmp_path / "rec"), "--arm", "both", "--camera-model", cam]) == 2
    assert "has no views with the right arm" in capsys.readouterr().err


def test_check_on_recorded_images_and_on_new_simulated_poses(
    calibrated: tuple[Path, dict[str, Any]], tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    out, _ = calibrated
    base = ["calibrate", "check", "--rig", str(SIM), "--camera-model", str(out / "cam.yaml")]
    capsys.readouterr()
    assert main([*base, "--images", str(out / "rec"), "--out", str(tmp_path / "ov"), "--max-px", "1", "--json"]) == 0
    text = capsys.readouterr().out
    summary = json.loads(text.strip().splitlines()[-1])
    assert "left arm: gripper points vs truth" in text and "board corners by FK" in text
    for side in ("left", "right"):
        arm = summary["arms"][side]
        assert arm["gripper_err_max_px"] <= 1.0  # at the rig's 128×128
        assert arm["board_reproj_rms_px"] <= 0.5 and arm["board_corners"] >= 100  # mounts from cam.json; 24 per view
    assert len(list((tmp_path / "ov").glob("check_*.png"))) == 10 and (tmp_path / "ov" / "check.json").is_file()
    assert main([*base, "--images", str(out / "rec"), "--max-px", "1e-9"]) == 1  # a threshold it cannot meet
    assert "check failed" in capsys.readouterr().err
    assert main([*base, "--sim", "--arm", "right", "--poses", "2", "--out", str(tmp_path / "sim")]) == 0
    text = capsys.readouterr().out
    assert "right arm: 2 board poses chosen" in text and "right arm: gripper points vs truth" in text
    assert len(list((tmp_path / "sim").glob("check_*.png"))) == 2
