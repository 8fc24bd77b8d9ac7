"""``pilworld control-video`` and ``pilworld bench control-video`` end to end, through ``main``."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import cv2
import numpy as np
import pytest

from pilworld.cli.main import main
from pilworld.control_video.examples import HOME_Q14, reach_and_grasp_chunk
from pilworld.data.video_codec import decode_video as read_video

ROOT = Path(__file__).resolve().parents[3]
SIM = ROOT / "configs" / "rig" / "sim_dual_ur5e.yaml"


@pytest.fixture
def chunk_file(tmp_path: Path) -> Path:
    path = tmp_path / "chunk.npy"
    np.save(path, reach_and_grasp_chunk())
    return path


def test_mp4_output(tmp_path: Path, chunk_file: Path, capsys: pytest.CaptureFixture[str]) -> None:
    out = tmp_path / "out" / "gamma.mp4"
    assert main(["control-video", "--rig", str(SIM), "--actions", str(chunk_file), "--out", str(out), "--json"]) == 0
    summary = json.loads(capsys.readouterr().out.strip().splitlines()[-1])
    assert summary["frames"] == 15 and summary["markers_drawn"] == 30 and summary["fps"] == pytest.approx(10.0)
    frames = read_video(out)
    assert frames.shape == (15, 128, 128, 3)
    # Lossy, but the red (left) and blue (right) markers survive encoding.
    assert frames[0, ..., 0].max() > 200 and frames[0, ..., 2].max() > 200


def test_png_sheet_and_rounds(tmp_path: Path, chunk_file: Path, capsys: pytest.CaptureFixture[str]) -> None:
    rounds = np.stack([reach_and_grasp_chunk(), reach_and_grasp_chunk()[::-1]])
    rounds_file = tmp_path / "rounds.npy"
    np.save(rounds_file, rounds)
    prev = tmp_path / "prev.npy"
    np.save(prev, HOME_Q14)
    out = tmp_path / "sheet.png"
    args = ["control-video", "--rig", str(SIM), "--actions", str(rounds_file), "--out", str(out)]
    assert main([*args, "--previous-state", str(prev), "--size", "96x64", "--json"]) == 0
    summary = json.loads(capsys.readouterr().out.strip().splitlines()[-1])
    assert summary["frames"] == 30 and summary["rounds"] == 2 and summary["image_size"] == [96, 64]
    sheet = cv2.imread(str(out))
    assert sheet.shape == (6 * 64 + 5 * 2, 5 * 96 + 4 * 2, 3)  # 30 frames in 5 columns, 2-px gaps


@pytest.mark.parametrize(
    ("content", "message"),
    [
        (np.zeros((50, 13)), r"expected shape \(H, 14\) or \(R, H, 14\), got \(50, 13\)"),
        (np.zeros((30, 14)), "chunk has 30 steps but K·Δ"),
        (np.array([[np.nan] * 14] * 50), "non-finite value nan at index"),
        (np.array(["a", "b"]), "expected real numbers"),
        (np.array([{"a": 1}], dtype=object), "not a plain numeric .npy"),  # pickled: refused, never loaded
    ],
)
def test_bad_actions_give_one_clear_line(
    tmp_path: Path, content: np.ndarray, message: str, capsys: pytest.CaptureFixture[str]
) -> None:
    bad = tmp_path / "bad.npy"
    np.save(bad, content, allow_pickle=True)
    code = main(["control-video", "--rig", str(SIM), "--actions", str(bad), "--out", str(tmp_path / "x.mp4")])
    err = capsys.readouterr().err
    assert code == 2
    assert err.startswith("pilworld: error: --actions") or "--actions" in err
    assert len(err.strip().splitlines()) == 1
    import re

    assert re.search(message, err), err


def test_missing_files_and_bad_suffix(tmp_path: Path, chunk_file: Path, capsys: pytest.CaptureFixture[str]) -> None:
    assert (
        main(
            [
                "control-video",
                "--rig",
                str(tmp_path / "nope.yaml"),
                "--actions",
                str(chunk_file),
                "--out",
                str(tmp_path / "x.mp4"),
            ]
        )
        == 2
    )
    assert "config file not found" in capsys.readouterr().err
    assert (
        main(
            [
                "control-video",
                "--rig",
                str(SIM),
                "--actions",
                str(tmp_path / "none.npy"),
                "--out",
                str(tmp_path / "x.mp4"),
            ]
        )
        == 2
    )
    assert "--actions: file not found" in capsys.readouterr().err
    assert (
        main(["control-video", "--rig", str(SIM), "--actions", str(chunk_file), "--out", str(tmp_path / "x.gif")]) == 2
    )
    assert "unsupported file type '.gif'" in capsys.readouterr().err
    assert (
        main(
            [
                "control-video",
                "--rig",
                str(SIM),
                "--actions",
                str(chunk_file),
                "--size",
                "big",
                "--out",
                str(tmp_path / "x.png"),
            ]
        )
        == 2
    )
    assert "--size: expected WIDTHxHEIGHT" in capsys.readouterr().err


def test_bench_prints_json_last_line(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["bench", "control-video", "--chunks", "40", "--batch", "16", "--repeats", "1", "--json"]) == 0
    result = json.loads(capsys.readouterr().out.strip().splitlines()[-1])
    assert result["frames_per_s"] > 0 and result["K"] == 15 and result["image_size"] == [128, 128]
    assert result["chunks"] == 40 and 0.5 < result["markers_drawn_fraction"] <= 1.0


def test_console_entry_point_runs() -> None:
    out = subprocess.run(
        [sys.executable, "-m", "pilworld", "--help"], capture_output=True, text=True, check=True, timeout=120
    ).stdout
    assert "control-video" in out and "bench" in out
