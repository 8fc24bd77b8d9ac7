"""Hand-eye calibration on the simulated rig against its known ``T_cam_base``.

The default tests use few poses at a low resolution (seconds); the acceptance run (20 poses per arm at
1024², ≤ 2 mm, ≤ 0.2°, gripper points ≤ 1 px at 128×128) is marked slow.
"""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path

import numpy as np
import pytest
import yaml

from calib.camera_model import CameraModel
from calib.handeye import DegenerateMotionError
from calib.rotations import pose_difference, rigid, rotation_exp
from pilworld.calibration.check import check_views, gripper_reprojection_errors
from pilworld.calibration.collect import move_to
from pilworld.calibration.recording import RecordedView, Recording
from pilworld.calibration.sim_cameras import sim_calibration_camera
from pilworld.calibration.sim_handeye import held_out_states, record_sim, run_sim_handeye
from pilworld.calibration.sim_truth import truth_errors
from pilworld.calibration.solve_arms import solve_recording
from pilworld.config.rig import RigConfig
from pilworld.control_video.gamma import ControlVideo
from pilworld.types import LEFT_ARM
from simrig.board_mount import BoardMount
from simrig.robot import SimRobot

ROOT = Path(__file__).resolve().parents[3]
SIM = ROOT / "configs" / "rig" / "sim_dual_ur5e.yaml"
KEYS = (
    "handeye_trans_err_mm",
    "handeye_rot_err_deg",
    "gripper_reproj_err_px",
    "rotation_span_deg",
    "poses",
    "residual_rms_px",
    "seconds",
)


@pytest.fixture(scope="module")
def rig() -> RigConfig:
    return RigConfig.load(SIM)


@pytest.fixture(scope="module")
def recording(rig: RigConfig) -> Recording:
    """Six poses per arm at 512² (the default suite's budget); the acceptance run uses 20 at 1024²."""
    return record_sim(rig, "both", poses=6, seed=0, resolution=512)


def test_both_arms_recover_the_true_camera(rig: RigConfig, recording: Recording) -> None:
    assert recording.camera is not None and recording.truth is not None
    assert len(recording.for_arm("left")) == len(recording.for_arm("right")) == 6
    outcome = solve_recording(recording.views, recording.camera, recording.board, rig.kinematics, "both")
    truth = truth_errors(rig, outcome, recording.truth, held_out_states(rig, ("left", "right"), recording.board, 0))
    print({k: v for k, v in truth.items() if not isinstance(v, dict)})
    assert truth["translation_err_mm"] <= 2.0
    assert truth["rotation_err_deg"] <= 0.2
    assert truth["gripper_reproj_err_px"] <= 1.0 and truth["gripper_points"] >= 20
    for side, err in truth["board_mount_err"].items():
        assert err["translation_mm"] <= 2.0, side
    both = outcome.both
    assert both is not None and set(outcome.per_arm) == {"left", "right"}
    dt, dr = pose_difference(outcome.per_arm["left"].T_cam_base, outcome.per_arm["right"].T_cam_base)
    assert both.disagreement_mm == pytest.approx(dt * 1e3) and both.disagreement_deg == pytest.approx(dr)
    assert both.disagreement_mm <= 2.0
    assert both.rms_px <= 0.3 and outcome.residual_rms_px == both.rms_px
    for result in outcome.per_arm.values():
        assert result.motion.rotation_span_deg >= 40.0 and not result.skipped
        assert set(result.closed_form) == {"shah", "park"}
        for estimate in result.opencv.values():  # empty on OpenCV 5.x: the cross-check is optional
            assert estimate.translation_diff_m <= 0.01
    assert np.array_equal(outcome.camera.K, recording.camera.K)


def test_recorded_folder_round_trip(rig: RigConfig, recording: Recording, tmp_path: Path) -> None:
    recording.save(tmp_path / "rec")
    assert sorted(p.name for p in (tmp_path / "rec").iterdir())[:2] == ["000.png", "001.png"]
    loaded = Recording.load(tmp_path / "rec")
    assert len(loaded.views) == len(recording.views) and loaded.rig == rig.name
    for a, b in zip(recording.views, loaded.views, strict=True):
        assert a.arm == b.arm and np.array_equal(a.image, b.image) and np.array_equal(a.state, b.state)
    assert loaded.camera == recording.camera and loaded.board == recording.board
    assert loaded.truth is not None and recording.truth is not None
    assert np.array_equal(loaded.truth.T_cam_base, recording.truth.T_cam_base)
    assert loaded.extra["seed"] == 0
    assert loaded.camera is not None and recording.camera is not None
    live = solve_recording(recording.views, recording.camera, recording.board, rig.kinematics, "right")
    offline = solve_recording(loaded.views, loaded.camera, loaded.board, rig.kinematics, "right")
    assert np.allclose(live.T_cam_base, offline.T_cam_base, atol=1e-12)  # PNG is lossless: the same answer


def test_bad_recordings_are_refused(recording: Recording, tmp_path: Path) -> None:
    with pytest.raises(FileNotFoundError, match="recording folder not found"):
        Recording.load(tmp_path / "nope")
    (tmp_path / "empty").mkdir()
    with pytest.raises(FileNotFoundError, match=r"no poses\.json"):
        Recording.load(tmp_path / "empty")
    recording.save(tmp_path / "rec")
    (tmp_path / "rec" / "003.png").unlink()
    with pytest.raises(ValueError, match=r"views\[3\]: cannot read image"):
        Recording.load(tmp_path / "rec")
    with pytest.raises(ValueError, match="state"):
        RecordedView(name="x", arm="left", image=np.zeros((4, 4), np.uint8), state=np.zeros(13))


def test_too_few_usable_views_raise(rig: RigConfig, recording: Recording) -> None:
    assert recording.camera is not None
    left = recording.for_arm("left")
    with pytest.raises(DegenerateMotionError, match=r"left arm: too few poses: got 2"):
        solve_recording(left[:2], recording.camera, recording.board, rig.kinematics, "left")
    blank = [RecordedView(v.name, v.arm, np.full_like(v.image, 128), v.state) for v in left[2:]]
    with pytest.raises(DegenerateMotionError, match=r"too few poses: got 2.*4 of 6 views skipped: 0 corners detected"):
        solve_recording([*left[:2], *blank], recording.camera, recording.board, rig.kinematics, "left")
    with pytest.raises(ValueError, match="image is 512x512 but the camera model is 1024x1024"):
        solve_recording(left, recording.camera.resized(1024, 1024), recording.board, rig.kinematics, "left")


@pytest.fixture(scope="module")
def wrist_views(rig: RigConfig, recording: Recording) -> Iterator[list[RecordedView]]:
    """Views of the first left pose with only the wrist joints turned (one axis, then tiny rotations)."""
    mount = BoardMount.beside_tcp(recording.board, "left")
    base = recording.for_arm("left")[0].state.copy()
    views = []
    with SimRobot(rig, board_mount=mount) as robot:
        turns = [
            ("w0", 0.0, 0.0),
            ("w1", 0.0, 12.0),
            ("w2", 0.0, -12.0),
            ("w3", 0.0, 24.0),
            ("t1", 1.5, 0.5),
            ("t2", -1.0, 1.0),
        ]
        for name, dq5, dq6 in turns:  # degrees of wrist 2 and wrist 3
            target = base.copy()
            target[LEFT_ARM.start + 4] += np.radians(dq5)
            target[LEFT_ARM.start + 5] += np.radians(dq6)
            state = move_to(robot, target, min_duration_s=1.0, settle_s=0.3)
            views.append(RecordedView(name, "left", robot.render("cam_high", 512, 512), state))
    yield views


def test_rotation_about_a_single_axis_raises(
    rig: RigConfig, recording: Recording, wrist_views: list[RecordedView]
) -> None:
    assert recording.camera is not None
    with pytest.raises(DegenerateMotionError, match=r"left arm: rotations about a single axis"):
        solve_recording(wrist_views[:4], recording.camera, recording.board, rig.kinematics, "left")


def test_small_rotations_raise(rig: RigConfig, recording: Recording, wrist_views: list[RecordedView]) -> None:
    assert recording.camera is not None
    small = [wrist_views[0], wrist_views[4], wrist_views[5]]  # wrist turns of 1-2.5°
    with pytest.raises(DegenerateMotionError, match=r"left arm: rotation span too small"):
        solve_recording(small, recording.camera, recording.board, rig.kinematics, "left")


def test_check_views_measures_gripper_and_board_errors(rig: RigConfig, recording: Recording) -> None:
    assert recording.camera is not None and recording.truth is not None
    truth = recording.truth.T_cam_base
    exact = check_views(
        recording.views,
        recording.camera.with_pose(truth),
        rig,
        truth_T_cam_base=truth,
        board=recording.board,
        T_tcp_board=recording.truth.T_tcp_board,
    )
    assert exact.gripper_err_px["left"].size >= 6 and float(exact.gripper_err_px["left"].max()) < 1e-9
    assert exact.board_err_px["left"].size == 6 * recording.board.n_corners
    assert float(np.sqrt(np.mean(exact.board_err_px["right"] ** 2))) < 0.3  # detector noise only, at 512²
    assert set(exact.overlays) == {v.name for v in recording.views}
    assert exact.overlays[recording.views[0].name].shape == (512, 512, 3)
    shifted = rigid(rotation_exp([0.0, 0.0, 0.002]), [0.01, 0.0, 0.0]) @ truth  # 1 cm and 0.11° off
    off = check_views(recording.views, recording.camera.with_pose(shifted), rig, truth_T_cam_base=truth)
    small = rig.head_camera_model
    assert float(off.gripper_err_px["right"].max()) > 1.0  # ~1 cm at ~1 m is ~1.5 px at 128² (f ≈ 151 px)
    direct = gripper_reprojection_errors(rig, small, shifted, [v.state for v in recording.views])
    assert np.allclose(np.sort(direct["right"]), np.sort(off.gripper_err_px["right"]))
    assert not off.board_err_px["left"].size  # no board check without the mounts
    summary = off.to_dict()
    assert summary["rig_image_size"] == [128, 128] and "gripper_err_max_px" in summary["arms"]["left"]
    assert any("gripper points vs truth" in line for line in off.lines())


def test_sim_calibration_camera_scales_the_intrinsics(rig: RigConfig) -> None:
    big = sim_calibration_camera(rig, 1024)
    assert big == rig.head_camera_model.resized(1024, 1024)
    with pytest.raises(ValueError, match="resolution"):
        sim_calibration_camera(rig, 4)


def test_the_rig_points_at_the_calibration_file_and_the_control_video_uses_it(
    rig: RigConfig, recording: Recording, tmp_path: Path
) -> None:
    assert recording.camera is not None
    outcome = solve_recording(recording.views, recording.camera, recording.board, rig.kinematics, "left")
    states = np.array([v.state for v in recording.views])
    stride_actions = np.repeat(states[:5], 3, axis=0)[None]  # (1, K = 15, 14): the calibration poses as a chunk
    # A visibly different pose (3 cm, 1°) as well, to prove the control video draws with the file's camera.
    for T in (outcome.T_cam_base, rigid(rotation_exp([0.0, 0.0175, 0.0]), [0.03, 0.0, 0.0]) @ outcome.T_cam_base):
        outcome.camera.with_pose(T).to_yaml(tmp_path / "head_camera.yaml")
        raw = yaml.safe_load(SIM.read_text(encoding="utf-8"))
        raw["head_camera"] = {"file": "head_camera.yaml"}  # relative to the rig file
        (tmp_path / "rig.yaml").write_text(yaml.safe_dump(raw), encoding="utf-8")
        calibrated = RigConfig.load(tmp_path / "rig.yaml")
        model = calibrated.head_camera_model
        assert np.array_equal(model.T_cam_base, CameraModel.from_yaml(tmp_path / "head_camera.yaml").T_cam_base)
        assert (model.width, model.height) == (128, 128)
        assert np.allclose(model.K, rig.head_camera_model.K, atol=1e-9)  # 512² letterboxed back to 128²
        gamma = ControlVideo.from_rig(calibrated)
        assert gamma.camera is model
        geo = gamma.geometry(stride_actions)
        expected, _ = model.project(calibrated.kinematics.gripper_points(stride_actions[0]))
        assert np.allclose(geo.frame_uv[0], expected)
    design = ControlVideo.from_rig(rig).geometry(stride_actions)
    assert np.abs(design.frame_uv[0] - geo.frame_uv[0]).max() > 1.0  # the shifted file moves the markers


def test_run_sim_handeye_reports_the_benchmark_keys(rig: RigConfig) -> None:
    result = run_sim_handeye(rig, "right", poses=5, seed=2, resolution=512)
    print(result)
    assert set(KEYS) <= set(result) and all(isinstance(result[k], float) for k in KEYS)
    assert result["poses"] == 5
    assert result["handeye_trans_err_mm"] <= 2.0 and result["handeye_rot_err_deg"] <= 0.2
    assert result["gripper_reproj_err_px"] <= 1.0 and result["rotation_span_deg"] >= 40.0


@pytest.mark.slow
@pytest.mark.parametrize("arm", ["left", "right", "both"])
def test_acceptance_20_poses_at_1024(rig: RigConfig, arm: str) -> None:
    """Calibration acceptance (docs/calibration_bench.md):
    ≥ 15 poses, ≥ 40° span: ≤ 2 mm, ≤ 0.2°, gripper points ≤ 1 px at 128×128."""
    result = run_sim_handeye(rig, arm, poses=20, seed=0, resolution=1024)
    print(arm, result)
    assert result["poses"] >= (40 if arm == "both" else 20) * 0.75
    assert result["rotation_span_deg"] >= 40.0
    assert result["handeye_trans_err_mm"] <= 2.0
    assert result["handeye_rot_err_deg"] <= 0.2
    assert result["gripper_reproj_err_px"] <= 1.0
    if arm == "both":
        assert result["disagreement_mm"] <= 2.0 and result["disagreement_deg"] <= 0.2
