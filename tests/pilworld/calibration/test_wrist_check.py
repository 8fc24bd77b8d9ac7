"""``pilworld calibrate check --camera <wrist camera>``: held-out board corners of a calibrated wrist camera."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from calib.board import ChArUcoBoard
from calib.camera_model import CameraModel
from calib.rotations import rigid, rotation_exp
from pilworld.calibration.check import WristCheckResult, check_wrist_views
from pilworld.calibration.recording import Recording
from pilworld.calibration.rig_file import write_rig_with_camera as _write_rig
from pilworld.calibration.sim_handeye import record_sim_wrist, record_wrist_check_sim
from pilworld.calibration.solve import calibrate_wrist
from pilworld.cli.main import main
from pilworld.config.rig import RigConfig

ROOT = Path(__file__).resolve().parents[3]
SIM = ROOT / "configs" / "rig" / "sim_dual_ur5e.yaml"
RIG = RigConfig.load(SIM)
BOARD = ChArUcoBoard.from_yaml(ROOT / "configs" / "board" / "charuco_7x5_a4.yaml")
CAMERA = "cam_left_wrist"


@pytest.fixture(scope="module")
def calibrated(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A small left-wrist calibration (8 poses at 512²) and a rig copy pointing at it (``--write-rig``)."""
    out = tmp_path_factory.mktemp("wrist_check")
    recording = record_sim_wrist(RIG, CAMERA, board=BOARD, poses=8, seed=0, resolution=512)
    assert recording.camera is not None
    result = calibrate_wrist(recording.views, recording.camera, BOARD, RIG.kinematics, "left", CAMERA)
    result.camera_model().to_yaml(out / "w.yaml")
    (out / "w.json").write_text(json.dumps(result.to_dict()), encoding="utf-8")
    _write_rig(SIM, out / "rig.yaml", CAMERA, out / "w.yaml")
    return out


@pytest.fixture(scope="module")
def held_out(calibrated: Path) -> tuple[Recording, np.ndarray]:
    """5 held-out views at the calibration resolution, saved as a recorded folder."""
    recording, T_rig_board = record_wrist_check_sim(RigConfig.load(calibrated / "rig.yaml"), CAMERA, poses=5, seed=0)
    assert recording.camera is not None and recording.camera.width == 1024
    return recording, T_rig_board


def _check(recording: Recording, camera: CameraModel, T_rig_board: np.ndarray) -> WristCheckResult:
    return check_wrist_views(
        recording.views, camera, recording.board, RIG.kinematics, "left", T_rig_board, rig_size=(128, 128)
    )


def test_calibrated_mount_is_sub_pixel_and_a_wrong_one_is_not(
    calibrated: Path, held_out: tuple[Recording, np.ndarray]
) -> None:
    recording, T_rig_board = held_out
    rig = RigConfig.load(calibrated / "rig.yaml")
    model = CameraModel.from_yaml(calibrated / "w.yaml")
    camera = model.resized(1024, 1024)  # the held-out views are at 1024²: the intrinsics scale exactly
    assert np.allclose(rig.wrist_camera_model(CAMERA).T_cam_base, model.T_cam_base)
    good = _check(recording, camera, T_rig_board).to_dict()
    assert good["views_checked"] == 5 and not good["skipped"]
    assert good["overall"]["rms_px_at_rig_size"] < 0.2 and good["overall"]["max_px_at_rig_size"] < 0.6
    assert good["overall"]["rms_px"] == pytest.approx(good["overall"]["rms_px_at_rig_size"] * 8)
    # 5 mm and 1° off the calibrated mount (T_cam_tcp composed with a small camera-frame motion).
    delta = rigid(rotation_exp(np.radians([1.0, 0.0, 0.0])), np.array([0.005, 0.0, 0.0]))
    wrong = _check(recording, camera.with_pose(delta @ model.T_cam_base), T_rig_board).to_dict()
    assert wrong["overall"]["rms_px_at_rig_size"] > good["overall"]["rms_px_at_rig_size"] + 0.5
    assert wrong["overall"]["rms_px_at_rig_size"] > 5 * good["overall"]["rms_px_at_rig_size"]


def test_cli_checks_the_rigs_wrist_camera_on_the_simulator(
    calibrated: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    argv = ["calibrate", "check", "--rig", str(calibrated / "rig.yaml"), "--camera", CAMERA, "--poses", "3"]
    assert main([*argv, "--out", str(tmp_path), "--max-px", "0.5", "--json"]) == 0
    out = capsys.readouterr().out
    summary = json.loads(out.strip().splitlines()[-1])
    assert summary["camera"] == CAMERA and summary["arm"] == "left" and not summary["designed_mount"]
    assert summary["image_size"] == [512, 512] and summary["rig_image_size"] == [128, 128]
    assert summary["views_checked"] == 3 and summary["overall"]["rms_px_at_rig_size"] < 0.2
    assert len(list(tmp_path.glob("check_*.png"))) == 3 and (tmp_path / "check.json").is_file()
    assert "board corners by FK over 3 views" in out
    # --max-px is honoured.
    assert main([*argv, "--max-px", "0.0001"]) == 1
    assert "check failed" in capsys.readouterr().err


def test_cli_checks_a_recorded_folder_with_the_report(
    calibrated: Path, held_out: tuple[Recording, np.ndarray], tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    recording, _ = held_out
    folder = tmp_path / "rec"
    recording.save(folder)
    (folder / "camera.yaml").unlink()  # a real folder need not have one: the rig's model is scaled to 1024²
    argv = ["calibrate", "check", "--rig", str(calibrated / "rig.yaml"), "--camera", CAMERA, "--images", str(folder)]
    assert main([*argv, "--report", str(calibrated / "w.json"), "--json"]) == 0
    summary = json.loads(capsys.readouterr().out.strip().splitlines()[-1])
    assert summary["image_size"] == [1024, 1024] and summary["views_checked"] == 5
    assert summary["overall"]["rms_px_at_rig_size"] < 0.2
    # Without a file: the designed mount, with a note; the board pose from the folder's recorded truth.
    base = ["calibrate", "check", "--rig", str(SIM), "--camera", CAMERA, "--images", str(folder), "--json"]
    assert main(base) == 0
    out = capsys.readouterr().out
    assert f"note: {CAMERA} has no file:" in out
    assert json.loads(out.strip().splitlines()[-1])["designed_mount"] is True


def test_unknown_camera_is_a_one_line_error(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["calibrate", "check", "--rig", str(SIM), "--camera", "cam_top"]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1
    assert "unknown camera 'cam_top'" in err and "cam_high, cam_left_wrist, cam_right_wrist" in err
