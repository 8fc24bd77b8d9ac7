"""``pilworld calibrate intrinsics --live`` on the fake rig: the real OpenCV driver on the MJPEG fake, the
simulator holding the board up; the result against the simulated camera, a camera stall, and resume."""

from __future__ import annotations

import json
from pathlib import Path

import pytest
import yaml

from pilworld.cli.main import main
from pilworld.config.rig import RigConfig

ROOT = Path(__file__).resolve().parents[3]
FAKE = ROOT / "configs" / "rig" / "fake_dual_ur5e.yaml"
SIM = ROOT / "configs" / "rig" / "sim_dual_ur5e.yaml"


def _last_json(out: str) -> dict:  # type: ignore[type-arg]
    return dict(json.loads(out.strip().splitlines()[-1]))


def test_stream_sizes_are_validated(tmp_path: Path) -> None:
    cfg = yaml.safe_load(FAKE.read_text())
    cfg["hardware"]["fake"]["stream_sizes"] = {"cam_top": {"width": 768, "height": 768}}
    bad = tmp_path / "rig.yaml"
    bad.write_text(yaml.safe_dump(cfg))
    with pytest.raises(ValueError, match="unknown camera 'cam_top'"):
        RigConfig.load(bad)
    cfg["hardware"]["fake"]["stream_sizes"] = {"cam_high": {"width": 768, "height": 512}}
    bad.write_text(yaml.safe_dump(cfg))
    with pytest.raises(ValueError, match="another aspect"):
        RigConfig.load(bad)


def test_live_needs_a_hardware_rig(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    out = tmp_path / "camera.yaml"
    assert main(["calibrate", "intrinsics", "--live", "--out", str(out)]) == 2
    assert "--live: needs --rig" in capsys.readouterr().err
    assert main(["calibrate", "intrinsics", "--live", "--rig", str(SIM), "--out", str(out)]) == 2
    assert "no 'hardware:' section" in capsys.readouterr().err
    assert main(["calibrate", "intrinsics", "--live", "--rig", str(FAKE), "--camera", "cam_x", "--out", str(out)]) == 2
    assert "no camera 'cam_x'" in capsys.readouterr().err
    assert (
        main(["calibrate", "intrinsics", "--live", "--rig", str(FAKE), "--camera", "cam_left_wrist", "--out", str(out)])
        == 2
    )
    assert "holds the board up to the head camera (cam_high) only" in capsys.readouterr().err
    with pytest.raises(SystemExit):  # --images and --live are exclusive
        main(["calibrate", "intrinsics", "--live", "--images", str(tmp_path), "--out", str(out)])


@pytest.mark.slow
def test_live_intrinsics_on_the_fake_rig(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """Acceptance (docs/calibration.md):
    focal length within 1 %, principal point within 2 px of the simulated camera."""
    out = tmp_path / "camera.yaml"
    argv = ["calibrate", "intrinsics", "--live", "--rig", str(FAKE), "--out", str(out), "--json"]
    rc = main([*argv, "--preview", str(tmp_path / "preview.png")])
    text = capsys.readouterr().out
    assert rc == 0, text
    report = _last_json(text)
    truth, live = report["truth"], report["live"]
    assert abs(truth["fx_err_pct"]) < 1.0 and abs(truth["fy_err_pct"]) < 1.0, truth
    assert max(abs(e) for e in truth["principal_point_err_px"]) < 2.0, truth
    assert live["stop"] == "targets reached" and live["views"] >= 20 and report["coverage"] >= 0.8
    assert "vs the simulator's camera: focal length off by" in text and (tmp_path / "preview.png").is_file()
    assert len(list((tmp_path / "camera_views").glob("*.png"))) == live["views"] and out.is_file()
    # A second run into the same folder must not mix views silently.
    assert main(argv) == 2
    assert "already holds views; pass --resume" in capsys.readouterr().err


@pytest.mark.slow
def test_a_camera_stall_keeps_the_views_and_resume_finishes(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch
) -> None:
    """The fake camera stalls mid-collection: one line names it, exit 1, every kept view stays; --resume ends it."""
    from pilworld.calibration import rig_devices

    grab = rig_devices.RigCamera.grab
    views = tmp_path / "camera_views"
    stalled = []

    def stalling(self: rig_devices.RigCamera) -> tuple:  # type: ignore[type-arg]
        if not stalled and len(list(views.glob("*.png"))) >= 6 and self.fake is not None:
            self.fake.inject("cameras", "stall")  # the MJPEG fake stops sending; the driver sees the stream age
            stalled.append(True)
        return grab(self)

    monkeypatch.setattr(rig_devices.RigCamera, "grab", stalling)
    out = tmp_path / "camera.yaml"
    argv = ["calibrate", "intrinsics", "--live", "--rig", str(FAKE), "--out", str(out), "--json"]
    assert main(argv) == 1
    captured = capsys.readouterr()
    err = captured.err.strip().splitlines()
    assert len(err) == 1 and "collection stopped: cam_high" in err[0] and "rerun with --resume" in err[0], err
    kept = sorted(views.glob("*.png"))
    assert 0 < len(kept) < 20 and not out.exists()
    monkeypatch.setattr(rig_devices.RigCamera, "grab", grab)
    assert main([*argv, "--resume"]) == 0
    text = capsys.readouterr().out
    assert f"resumed: {len(kept)} views" in text
    report = _last_json(text)
    assert report["live"]["views"] >= 20 and abs(report["truth"]["fx_err_pct"]) < 1.0
    assert sorted(views.glob("*.png"))[: len(kept)] == kept  # the new views are numbered after the kept ones
