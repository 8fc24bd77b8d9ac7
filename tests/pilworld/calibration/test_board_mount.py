"""The simulated calibration board: its texture maps exactly onto its known 3-D corners.

Rendered by the rig's own head camera at calibration resolution, the detected corners must agree with
the projection of ``T_cam_base · T_rig_tcp(q) · T_tcp_board · P_k`` to well under half a pixel; otherwise
the simulated hand-eye acceptance would measure the texture, not the calibration.
"""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path

import numpy as np
import pytest

from calib.board import ChArUcoBoard
from calib.detect import BoardDetector
from pilworld.calibration.collect import collect_views
from pilworld.calibration.plan import PlannerSettings, plan_board_poses
from pilworld.calibration.sim_cameras import sim_calibration_camera
from pilworld.config.rig import RigConfig
from pilworld.types import ARM_LAYOUT
from simrig.board_mount import BOARD_TEXTURE_FILE, BoardMount
from simrig.poses import HOME_Q14
from simrig.robot import SimRobot
from simrig.scene import build_mjcf, compile_scene

ROOT = Path(__file__).resolve().parents[3]
SIM = ROOT / "configs" / "rig" / "sim_dual_ur5e.yaml"
A4 = ROOT / "configs" / "board" / "charuco_7x5_a4.yaml"
RESOLUTION = 1024


@pytest.fixture(scope="module")
def rig() -> RigConfig:
    return RigConfig.load(SIM)


@pytest.fixture(scope="module")
def board() -> ChArUcoBoard:
    return ChArUcoBoard.from_yaml(A4)


@pytest.fixture(scope="module")
def robot(rig: RigConfig, board: ChArUcoBoard) -> Iterator[SimRobot]:
    with SimRobot(rig, board_mount=BoardMount.beside_tcp(board, "right")) as r:
        yield r


def test_mount_geometry_and_validation(board: ChArUcoBoard) -> None:
    mount = BoardMount.beside_tcp(board, "left", gap_m=0.05)
    assert np.allclose(mount.T_tcp_board[:3, :3], np.eye(3))  # board z = tool z: the face looks back up the tool
    page = mount.page_corners_tcp()
    assert page[:, 0].min() == pytest.approx(0.05)  # the page starts gap_m beside the tool axis
    assert page[:, 1].mean() == pytest.approx(0.0)
    assert np.allclose(
        mount.corner_points_tcp()[0],
        [0.05 + board.margin_m + board.square_length_m, -board.size_m[1] / 2 + board.square_length_m, 0.0],
    )
    assert set(mount.assets()) == {BOARD_TEXTURE_FILE}
    with pytest.raises(ValueError, match="arm"):
        BoardMount.beside_tcp(board, "middle")
    with pytest.raises(ValueError, match="T_tcp_board"):
        BoardMount(board=board, arm="left", T_tcp_board=np.diag([2.0, 1.0, 1.0, 1.0]))
    with pytest.raises(ValueError, match="texture_ppm"):
        BoardMount(board=board, arm="left", T_tcp_board=np.eye(4), texture_ppm=1e6)


def test_scene_without_a_board_is_unchanged_and_with_one_compiles(rig: RigConfig, board: ChArUcoBoard) -> None:
    plain = build_mjcf(rig)
    assert "calibration_board" not in plain and "<asset>" not in plain
    mount = BoardMount.beside_tcp(board, "left")
    xml = build_mjcf(rig, board_mount=mount)
    model = compile_scene(xml, assets=mount.assets())
    geom = model.geom("left_calibration_board")
    assert model.body(int(geom.bodyid[0])).name == "left_tcp_frame"
    assert geom.contype[0] == 0 and geom.conaffinity[0] == 0  # visual only
    with pytest.raises(ValueError, match="does not compile"):
        compile_scene(xml)  # the texture must come through assets


def test_render_at_calibration_resolution_keeps_the_policy_size(robot: SimRobot) -> None:
    assert robot.render("cam_high").shape == (128, 128, 3)
    assert robot.render("cam_high", 320, 320).shape == (320, 320, 3)
    assert robot.observe().images["cam_high"].shape == (128, 128, 3)


def test_detected_corners_match_the_projected_3d_corners(rig: RigConfig, board: ChArUcoBoard, robot: SimRobot) -> None:
    assert robot.board_mount is not None
    mount = robot.board_mount
    camera = sim_calibration_camera(rig, RESOLUTION)
    assert np.allclose(camera.K, rig.head_camera_model.resized(RESOLUTION, RESOLUTION).K)
    plan = plan_board_poses(
        rig.kinematics, camera, board, mount.T_tcp_board, "right", HOME_Q14, PlannerSettings(poses=4), seed=3
    )
    views = collect_views(
        robot, plan, lambda: robot.render("cam_high", RESOLUTION, RESOLUTION), min_duration_s=0.5, settle_s=0.2
    )
    detector = BoardDetector(board)
    errors = []
    for view in views:
        detection = detector.detect(view.gray())
        assert detection.n_corners == board.n_corners  # the planner's visibility model kept every corner in view
        T = rig.kinematics.right.tcp_pose(view.state[ARM_LAYOUT["right"][0]]) @ mount.T_tcp_board
        truth, visible = camera.project(board.corner_points() @ T[:3, :3].T + T[:3, 3])
        assert visible.all()
        errors.append(detection.corners - truth[detection.corner_ids])
    d = np.concatenate(errors)
    e = np.linalg.norm(d, axis=1)
    # The mean residual is the mapping's bias (a texel offset or a mirrored axis shows here); the spread is
    # the detector's own sub-pixel noise.
    rms, bias = float(np.sqrt(np.mean(e**2))), float(np.linalg.norm(d.mean(axis=0)))
    print(f"board texture vs 3-D corners at {RESOLUTION}²: RMS {rms:.3f} px, max {e.max():.3f} px, bias {bias:.3f} px")
    assert rms < 0.15
    assert e.max() < 0.45
    assert bias < 0.05
