"""``pilworld control-video --style`` (Γ⁺) and ``pilworld bench control-video --style``, through ``main``."""

from __future__ import annotations

import json
from pathlib import Path

import cv2
import numpy as np
import pytest

from pilworld.cli.main import main
from pilworld.control_video.examples import reach_and_grasp_chunk, starting_at

ROOT = Path(__file__).resolve().parents[3]
SIM = ROOT / "configs" / "rig" / "sim_dual_ur5e.yaml"


@pytest.fixture
def chunk_file(tmp_path: Path) -> Path:
    from simrig.poses import HOME_Q14 as SIM_START

    path = tmp_path / "chunk.npy"
    np.save(path, starting_at(reach_and_grasp_chunk(), SIM_START))
    return path


def _last_json(capsys: pytest.CaptureFixture[str]) -> dict[str, object]:
    out: dict[str, object] = json.loads(capsys.readouterr().out.strip().splitlines()[-1])
    return out


def test_render_style_writes_every_view_side_by_side(
    tmp_path: Path, chunk_file: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    out = tmp_path / "render.png"
    argv = ["control-video", "--rig", str(SIM), "--actions", str(chunk_file), "--out", str(out)]
    assert main([*argv, "--style", "render", "--json"]) == 0
    summary = _last_json(capsys)
    assert summary["style"] == "render" and summary["frames"] == 15
    assert summary["views"] == ["cam_high", "cam_left_wrist", "cam_right_wrist"]
    sheet = cv2.imread(str(out))
    assert sheet is not None and sheet.shape[1] >= 5 * 3 * 128  # five frames a row, three views each
    assert sheet.any()


def test_prior_style_takes_a_simulated_start_and_refuses_without_one(
    tmp_path: Path, chunk_file: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    argv = ["control-video", "--rig", str(SIM), "--actions", str(chunk_file)]
    out = tmp_path / "prior.png"
    assert main([*argv, "--out", str(out), "--style", "render+markers+prior", "--task", "sort_cubes", "--json"]) == 0
    assert _last_json(capsys)["style"] == "render+markers+prior"
    sheet = cv2.imread(str(out))
    assert sheet is not None
    # The prior paints the table (light) where the render style alone would leave black.
    assert np.mean(sheet) > 60
    assert main([*argv, "--out", str(tmp_path / "x.png"), "--style", "prior"]) == 2
    err = capsys.readouterr().err
    assert "--style prior" in err and "--task" in err and len(err.strip().splitlines()) == 1


def test_unknown_style_is_one_line(tmp_path: Path, chunk_file: Path, capsys: pytest.CaptureFixture[str]) -> None:
    argv = ["control-video", "--rig", str(SIM), "--actions", str(chunk_file), "--out", str(tmp_path / "x.png")]
    assert main([*argv, "--style", "rendr"]) == 2
    err = capsys.readouterr().err.strip()
    assert "rendr" in err and "render+markers" in err and len(err.splitlines()) == 1


def test_bench_style_reports_latency_beside_the_world_model(capsys: pytest.CaptureFixture[str]) -> None:
    argv = ["bench", "control-video", "--style", "render", "--starts", "1", "--chunks-per-start", "2"]
    assert main([*argv, "--repeats", "1", "--json"]) == 0
    result = _last_json(capsys)
    assert result["style"] == "render" and result["chunks"] == 2
    assert isinstance(result["ms_per_chunk_p50"], float) and result["ms_per_chunk_p50"] > 0
    wm = result["world_model"]
    assert isinstance(wm, dict) and wm["chunk_latency_ms"] > 0
    assert result["ratio_to_world_model"] == pytest.approx(result["ms_per_chunk_p50"] / wm["chunk_latency_ms"])
