"""The board a person holds up to the head camera: poses a person would show, rendered where the model says."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from calib.board import ChArUcoBoard
from calib.detect import BoardDetector
from pilworld.config.rig import RigConfig
from simrig.board_mount import BoardMount
from simrig.hand_board import HandBoard, presentation_poses
from simrig.robot import SimRobot

ROOT = Path(__file__).resolve().parents[2]
RIG = RigConfig.load(ROOT / "configs" / "rig" / "sim_dual_ur5e.yaml")
BOARD = ChArUcoBoard.from_yaml(ROOT / "configs" / "board" / "charuco_7x5_a4.yaml")
SIZE = 512


def test_presentation_poses_cover_the_image_and_keep_the_board_in_view() -> None:
    camera = RIG.head_camera_model.resized(SIZE, SIZE)
    poses = presentation_poses(camera, BOARD, 32, seed=1)
    centres = []
    for T in poses:
        uv, visible = camera.project(BOARD.corner_points() @ T[:3, :3].T + T[:3, 3])
        assert visible.mean() >= 0.6
        centres.append(uv[visible].mean(axis=0) / SIZE)
    c = np.array(centres)
    assert c.min() < 0.25 and c.max() > 0.75  # the board visits the image's edges, not only its middle
    assert len(poses) == 32
    np.testing.assert_allclose(presentation_poses(camera, BOARD, 3, seed=1)[0], poses[0])  # seeded
    with pytest.raises(ValueError, match="count"):
        presentation_poses(camera, BOARD, 0)
    with pytest.raises(ValueError, match="could not fit"):
        presentation_poses(camera, BOARD, 2, distance_m=(0.05, 0.06))


def test_held_board_renders_where_the_model_puts_it() -> None:
    camera = RIG.head_camera_model.resized(SIZE, SIZE)
    detector = BoardDetector(BOARD)
    with SimRobot(RIG) as robot:
        q0 = robot.state().copy()
        with pytest.raises(ValueError, match="no hand board"):
            robot.hold_board(np.eye(4))
        robot.set_boards(hand_board=HandBoard(BOARD))
        np.testing.assert_allclose(robot.state(), q0, atol=1e-6)  # the arms stay where they stood
        assert detector.detect(robot.render("cam_high", SIZE, SIZE)).n_corners == 0  # parked out of view
        errors = []
        for T in presentation_poses(camera, BOARD, 4, seed=2):
            robot.hold_board(T)
            det = detector.detect(robot.render("cam_high", SIZE, SIZE))
            assert det.n_corners >= 6  # near the edges the board may stick out of the image
            uv, _ = camera.project(BOARD.corner_points()[det.corner_ids] @ T[:3, :3].T + T[:3, 3])
            errors.append(np.linalg.norm(uv - det.corners, axis=1).mean())
        assert max(errors) < 0.2, errors
        with pytest.raises(ValueError, match="rigid"):
            robot.hold_board(np.zeros((4, 4)))
        robot.hold_board(None)
        assert detector.detect(robot.render("cam_high", SIZE, SIZE)).n_corners == 0
        robot.set_boards(board_mount=BoardMount.beside_tcp(BOARD, "left"))  # the board moves to a gripper
        assert robot.hand_board is None and robot.board_mount is not None
        with pytest.raises(ValueError, match="no hand board"):
            robot.hold_board(None)
