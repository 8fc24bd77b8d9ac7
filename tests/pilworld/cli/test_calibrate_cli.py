"""``pilworld calibrate board|intrinsics`` end to end, through ``main``."""

from __future__ import annotations

import json
import re
from pathlib import Path

import cv2
import numpy as np
import pytest

from calib.board import ChArUcoBoard
from calib.camera_model import CameraModel
from calib.synthetic import synthetic_views
from pilworld.cli.main import main

ROOT = Path(__file__).resolve().parents[3]
A4 = ROOT / "configs" / "board" / "charuco_7x5_a4.yaml"


def test_board_writes_png_and_true_scale_pdf(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    assert (
        main(["calibrate", "board", "--config", str(A4), "--out", str(tmp_path / "out"), "--dpi", "100", "--json"]) == 0
    )
    summary = json.loads(capsys.readouterr().out.strip().splitlines()[-1])
    pdf = (tmp_path / "out" / "charuco_7x5_a4.pdf").read_bytes().decode("latin-1")
    box = re.search(r"/MediaBox \[0 0 (\S+) (\S+)\]", pdf)
    assert box is not None
    assert [float(box.group(1)), float(box.group(2))] == pytest.approx(summary["page_size_pt"], abs=1e-3)
    assert summary["page_size_mm"] == pytest.approx([265.0, 195.0])
    png = cv2.imread(summary["png"], cv2.IMREAD_GRAYSCALE)
    assert png is not None and png.shape == (768, 1043)  # 195 mm and 265 mm at 100 dpi


def test_intrinsics_from_a_folder(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    board = ChArUcoBoard.from_yaml(A4)
    K = np.array([[500.0, 0.0, 319.0], [0.0, 500.0, 241.0], [0.0, 0.0, 1.0]])
    truth = CameraModel(K=K, dist=[-0.1, 0.05, 0.0, 0.0, 0.0], T_cam_base=np.eye(4), width=640, height=480)
    images = tmp_path / "images"
    images.mkdir()
    for i, view in enumerate(synthetic_views(board, truth, 10, seed=7)):
        cv2.imwrite(str(images / f"img_{i:02d}.png"), view.image)
    cv2.imwrite(str(images / "empty.png"), np.full((480, 640), 128, np.uint8))
    (images / "notes.txt").write_text("not an image")
    out = tmp_path / "cam" / "camera.yaml"
    argv = ["calibrate", "intrinsics", "--images", str(images), "--board", str(A4), "--out", str(out), "--json"]
    assert main(argv) == 0
    text = capsys.readouterr().out
    report = json.loads(text.strip().splitlines()[-1])
    assert "empty.png" in text and "too_few_corners" in text and "coverage:" in text and "held-out RMS" in text
    assert report["n_views_used"] >= 8 and report["rms_px"] < 0.2 and report["held_out_rms_px"] < 0.3
    camera = CameraModel.from_yaml(out)
    assert camera.K[0, 0] == pytest.approx(500.0, rel=0.01) and camera.K[0, 2] == pytest.approx(319.0, abs=5.0)
    np.testing.assert_array_equal(camera.T_cam_base, np.eye(4))


def test_intrinsics_errors(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    argv = ["calibrate", "intrinsics", "--images", str(tmp_path), "--board", str(A4), "--out", str(tmp_path / "c.yaml")]
    assert main(argv) == 2
    assert "no images" in capsys.readouterr().err
    assert main([*argv, "--held-out", "1.5"]) == 2
    assert "--held-out" in capsys.readouterr().err
