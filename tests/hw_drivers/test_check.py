"""``pilworld robot check`` and ``pilworld bench drivers`` against the fake rig (and a rig with nothing attached)."""

from __future__ import annotations

import json
from pathlib import Path

import pytest
import yaml

from pilworld.bench.drivers import run_drivers_bench
from pilworld.cli.main import main

ROOT = Path(__file__).resolve().parents[2]
FAKE = ROOT / "configs" / "rig" / "fake_dual_ur5e.yaml"
REAL = ROOT / "configs" / "rig" / "real_dual_ur5e.yaml"


def test_robot_check_on_the_fake_rig(capsys: pytest.CaptureFixture[str]) -> None:
    rc = main(["robot", "check", "--rig", str(FAKE), "--json"])
    out = capsys.readouterr().out
    report = json.loads(out.strip().splitlines()[-1])
    assert rc == 0 and report["ok"], out
    devices = {d["device"]: d for d in report["devices"]}
    assert set(devices) == {
        "left arm",
        "right arm",
        "left gripper",
        "right gripper",
        "cam_high",
        "cam_left_wrist",
        "cam_right_wrist",
    }
    assert devices["left gripper"]["driver"] == "dynamixel" and devices["right gripper"]["driver"] == "robotiq"
    assert "safety normal" in devices["left arm"]["reading"]
    # The head camera streams its full resolution (hardware.fake.stream_sizes), the wrist cameras the rig's size.
    assert "768x768 frame" in devices["cam_high"]["reading"]
    assert "128x128 frame" in devices["cam_left_wrist"]["reading"]
    assert "7 of 7 devices ok" in out


def test_robot_check_names_every_missing_device(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """A real rig file whose devices are absent: every row fails with a typed error, exit status 1."""
    cfg = yaml.safe_load(REAL.read_text())
    cfg["head_camera"]["file"] = str((REAL.parent / cfg["head_camera"]["file"]).resolve())
    hw = cfg["hardware"]
    hw["arms"]["left"]["host"], hw["arms"]["right"]["host"] = "127.0.0.9", "127.0.0.10"  # nothing listens
    hw["arms"]["left"]["connect_timeout"] = hw["arms"]["right"]["connect_timeout"] = 1.0
    hw["arms"]["left"]["retries"] = hw["arms"]["right"]["retries"] = 0
    hw["grippers"]["left"]["port"] = str(tmp_path / "ttyUSB0")
    hw["grippers"]["right"]["port"] = str(tmp_path / "ttyUSB1")
    for cam in hw["cameras"].values():
        cam["source"] = "http://127.0.0.1:9/none.mjpg"
    rig = tmp_path / "absent.yaml"
    rig.write_text(yaml.safe_dump(cfg))
    rc = main(["robot", "check", "--rig", str(rig), "--json"])
    report = json.loads(capsys.readouterr().out.strip().splitlines()[-1])
    assert rc == 1 and not report["ok"]
    readings = {d["device"]: d["reading"] for d in report["devices"]}
    assert all(not d["ok"] for d in report["devices"])
    assert readings["left arm"].startswith("DeviceConnectionError") and "127.0.0.9" in readings["left arm"]
    assert readings["left gripper"].startswith("DeviceConnectionError") and "ttyUSB0" in readings["left gripper"]
    assert readings["right gripper"].startswith("DeviceConnectionError") and "ttyUSB1" in readings["right gripper"]
    assert readings["cam_high"].startswith(("DeviceConnectionError", "DeviceTimeoutError"))


def test_robot_check_refuses_a_simulated_rig(capsys: pytest.CaptureFixture[str]) -> None:
    # --debug prints the traceback and keeps the documented exit status (2: bad input).
    rc = main(["--debug", "robot", "check", "--rig", str(ROOT / "configs" / "rig" / "sim_dual_ur5e.yaml")])
    err = capsys.readouterr().err
    assert rc == 2 and "no 'hardware:' section" in err and "Traceback" in err


def test_drivers_bench_reports_every_figure() -> None:
    r = run_drivers_bench(FAKE, seconds=2.0)
    for key in ("servo_rate_hz", "servo_period_p99_ms", "dynamixel_roundtrip_ms", "robotiq_roundtrip_ms", "camera_fps"):
        assert r[key] is not None and r[key] > 0, key
    assert set(r["servo"]) == {"left", "right"}
    # The figures themselves are the bench's output, not pass/fail criteria (no wall-clock rates in tests):
    # here, that each comes from real traffic and is reported consistently.
    assert r["servo_rate_target_hz"] == 500 and r["camera_fps_served"] > 0
    for side in ("left", "right"):
        s = r["servo"][side]
        assert s["cycles"] > 0 and s["period_p50_ms"] <= s["period_p99_ms"] <= s["period_max_ms"], s
    assert r["servo_rate_hz"] == min(s["rate_hz"] for s in r["servo"].values())
    assert r["camera_fps"] == min(r["camera_fps_per_camera"].values())
    assert {g["side"] for g in r["grippers"].values()} == {"left", "right"}
    # what the driver tests no longer time: set_target and read_latest, per device
    assert set(r["gripper_set_target"]) == {"left", "right"}
    assert set(r["camera_read_latest"]) == set(r["camera_fps_per_camera"])
    for figures in (*r["gripper_set_target"].values(), *r["camera_read_latest"].values()):
        assert 0 < figures["median_ms"] <= figures["p99_ms"], figures
    assert r["gripper_set_target_p99_ms"] == max(v["p99_ms"] for v in r["gripper_set_target"].values())
