"""``pilworld calibrate handeye`` and ``check`` on the fake rig: the robot moved through the real drivers (ur_rtde
against the fake controllers, OpenCV on the MJPEG fake), the result against the simulator's truth, faults injected
mid-collection (protective stop, camera stall, a refused pose) and ``--resume``, and no motion without confirmation."""

from __future__ import annotations

import json
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest

from hw_drivers.fakes.rig import FakeRig
from pilworld.cli.main import main

ROOT = Path(__file__).resolve().parents[3]
FAKE = ROOT / "configs" / "rig" / "fake_dual_ur5e.yaml"
POSES = "6"


def _last_json(out: str) -> dict[str, Any]:
    return dict(json.loads(out.strip().splitlines()[-1]))


@pytest.fixture
def fakes(monkeypatch: pytest.MonkeyPatch) -> Iterator[list[FakeRig]]:
    """Every FakeRig the commands start, so a test can inject faults into it."""
    started: list[FakeRig] = []
    start = FakeRig.start

    def recording_start(self: FakeRig) -> Any:
        started.append(self)
        return start(self)

    monkeypatch.setattr(FakeRig, "start", recording_start)
    yield started


def _fault_after(monkeypatch: pytest.MonkeyPatch, fakes: list[FakeRig], views: int, device: str, kind: str) -> None:
    """Inject ``kind`` into the fake ``device`` once ``views`` views are recorded."""
    from pilworld.calibration import rig_collection

    add = rig_collection.ViewStore.add

    def add_then_fault(self: rig_collection.ViewStore, view: Any, pose: str) -> str:
        name = add(self, view, pose)
        if self.count == views:
            fakes[-1].inject(device, kind)
        return name

    monkeypatch.setattr(rig_collection.ViewStore, "add", add_then_fault)


@pytest.mark.slow
def test_no_motion_without_confirmation(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch
) -> None:
    """No TTY and no --yes: the plan is printed, nothing is sent to the arms, exit 1 with one line."""
    from hw_drivers.dual_arm import DualArmRobot

    sent: list[Any] = []
    send = DualArmRobot.send_action
    monkeypatch.setattr(DualArmRobot, "send_action", lambda self, a: sent.append(a) or send(self, a))
    out = tmp_path / "head_camera.yaml"
    rc = main(["calibrate", "handeye", "--rig", str(FAKE), "--arm", "left", "--poses", POSES, "--out", str(out)])
    captured = capsys.readouterr()
    assert rc == 1 and sent == [] and not out.exists()
    assert "plan:" in captured.out and "left arm: 6 poses; TCP within x" in captured.out
    assert "rad/s" in captured.out and "min" in captured.out
    err = captured.err.strip().splitlines()
    assert len(err) == 1 and "the robot did not move" in err[0] and "--yes" in err[0]


@pytest.mark.slow
def test_handeye_and_check_on_the_fake_rig(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """Acceptance (docs/calibration.md):
    within 2 mm and 0.3° of the simulator's truth; the check within 1 px at 128²."""
    out = tmp_path / "head_camera.yaml"
    argv = ["calibrate", "handeye", "--rig", str(FAKE), "--arm", "both", "--out", str(out), "--yes", "--json"]
    assert main([*argv, "--poses", "10"]) == 0
    text = capsys.readouterr().out
    report = _last_json(text)
    truth = report["truth"]
    assert truth["translation_err_mm"] < 2.0 and truth["rotation_err_deg"] < 0.3, truth
    assert truth["gripper_reproj_err_px"] < 1.0 and report["poses"] >= 18  # a view may fail the solver's checks
    assert "fake rig: the simulator mounts the board on the right gripper" in text
    assert "the left arm returns to the start pose" in text
    views = tmp_path / "head_camera_views"
    outcome = json.loads((views / "plan.json").read_text())["outcome"]
    recorded = [n for n, o in outcome.items() if o.startswith("recorded")]
    assert len(outcome) == 20 and len(recorded) == len(list(views.glob("*.png"))) >= 18
    check = ["calibrate", "check", "--rig", str(FAKE), "--camera-model", str(out), "--out", str(tmp_path / "check")]
    assert main([*check, "--yes", "--json", "--max-px", "1.0"]) == 0
    result = _last_json(capsys.readouterr().out)
    for arm in ("left", "right"):
        entry = result["arms"][arm]
        assert entry["gripper_err_max_px"] < 1.0 and entry["board_reproj_rms_px_at_rig_size"] < 1.0, entry
    assert len(list((tmp_path / "check").glob("check_*.png"))) == result["views"] >= 10


@pytest.mark.slow
def test_protective_stop_and_a_refused_pose_then_resume(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch, fakes: list[FakeRig]
) -> None:
    from pilworld.calibration import rig_collection

    plan_of = rig_collection.ArmPlan.from_pose_plan

    def with_a_refused_pose(plan: Any, hold: Any) -> rig_collection.ArmPlan:
        arm_plan = plan_of(plan, hold)
        arm_plan.commands[4][5] = 7.0  # wrist 3 beyond its joint limit: the safety filter refuses the pose
        return arm_plan

    monkeypatch.setattr(rig_collection.ArmPlan, "from_pose_plan", staticmethod(with_a_refused_pose))
    _fault_after(monkeypatch, fakes, 2, "left_arm", "protective_stop")
    out = tmp_path / "head_camera.yaml"
    argv = ["calibrate", "handeye", "--rig", str(FAKE), "--arm", "left", "--poses", POSES, "--out", str(out), "--yes"]
    assert main(argv) == 1
    captured = capsys.readouterr()
    err = captured.err.strip().splitlines()
    assert len(err) == 1 and "collection stopped: left arm: protective stop" in err[0], err
    assert "the arms are stopped; 2 view(s) kept" in err[0] and "--resume" in err[0]
    views = tmp_path / "head_camera_views"
    before = {p.name: p.read_bytes() for p in views.glob("*.png")}
    assert sorted(before) == ["000.png", "001.png"] and not out.exists()
    # --resume: the stored plan (the refused pose in it), a new fake rig without the fault; it finishes.
    assert main([*argv, "--resume", "--json"]) == 0
    text = capsys.readouterr().out
    assert "left arm: 4 poses (2 done earlier)" in text
    assert "left_004: skipped — refused by the safety filter: " in text and "joint_limits" in text
    assert {p.name: p.read_bytes() for p in views.glob("*.png") if p.name in before} == before
    report = _last_json(text)
    assert report["poses"] == 5 and report["truth"]["translation_err_mm"] < 2.0
    plan = json.loads((views / "plan.json").read_text())
    assert plan["outcome"]["left_004"].startswith("skipped: refused by the safety filter")


@pytest.mark.slow
def test_camera_stall_then_resume(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch, fakes: list[FakeRig]
) -> None:
    _fault_after(monkeypatch, fakes, 3, "cameras", "stall")
    out = tmp_path / "head_camera.yaml"
    argv = ["calibrate", "handeye", "--rig", str(FAKE), "--arm", "right", "--poses", POSES, "--out", str(out), "--yes"]
    assert main(argv) == 1
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "collection stopped: cam_high" in err[0] and "3 view(s) kept" in err[0], err
    assert main([*argv, "--resume", "--json"]) == 0
    report = _last_json(capsys.readouterr().out)
    assert report["poses"] == 6 and report["truth"]["translation_err_mm"] < 2.0


@pytest.mark.slow
def test_ctrl_c_keeps_the_views_and_resume_does_not_repeat_them(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch
) -> None:
    """Ctrl-C right after a view is written (before plan.json knows): the arms stop, and resume neither loses
    nor repeats that view."""
    from pilworld.calibration import rig_collection

    add = rig_collection.ViewStore.add

    def add_then_interrupt(self: rig_collection.ViewStore, view: Any, pose: str) -> str:
        name = add(self, view, pose)
        if self.count == 2:
            raise KeyboardInterrupt
        return name

    monkeypatch.setattr(rig_collection.ViewStore, "add", add_then_interrupt)
    out = tmp_path / "head_camera.yaml"
    argv = ["calibrate", "handeye", "--rig", str(FAKE), "--arm", "left", "--poses", POSES, "--out", str(out), "--yes"]
    assert main(argv) == 1
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "collection stopped: interrupted (Ctrl-C); the arms are stopped; 2 view(s)" in err[0]
    monkeypatch.setattr(rig_collection.ViewStore, "add", add)
    assert main([*argv, "--resume", "--json"]) == 0
    report = _last_json(capsys.readouterr().out)
    poses = [v["pose"] for v in json.loads((tmp_path / "head_camera_views" / "poses.json").read_text())["views"]]
    assert poses == [f"left_{i:03d}" for i in range(6)] and report["poses"] == 6
