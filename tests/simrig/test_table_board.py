"""A ChArUco board lying on the simulated table: its pose, validation and the MJCF it adds."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from calib.board import ChArUcoBoard
from pilworld.config.rig import RigConfig
from simrig.board_mount import BoardMount
from simrig.scene import build_mjcf, compile_scene
from simrig.table_board import TableBoard

ROOT = Path(__file__).resolve().parents[2]
RIG = RigConfig.load(ROOT / "configs" / "rig" / "sim_dual_ur5e.yaml")
BOARD = ChArUcoBoard.from_yaml(ROOT / "configs" / "board" / "charuco_7x5_a4.yaml")


def test_flat_board_is_centred_face_up_and_turned() -> None:
    table = TableBoard.flat(BOARD, (0.1, -0.2), yaw_deg=90.0, face_height_m=0.005)
    assert np.allclose(table.centre_rig(), [0.1, -0.2, 0.005])
    R = table.T_rig_board[:3, :3]
    assert np.allclose(R[:, 2], [0.0, 0.0, -1.0])  # board z into the board: down
    assert np.allclose(R[:, 0], [0.0, 1.0, 0.0], atol=1e-12)  # board x turned 90° from rig x
    page = table.to_rig(table.page_corners_board())
    assert np.allclose(page[:, 2], 0.005)
    assert TableBoard.for_arm(BOARD, "right").centre_rig()[1] < 0.0 < TableBoard.for_arm(BOARD, "left").centre_rig()[1]


def test_bad_inputs_name_the_field() -> None:
    with pytest.raises(ValueError, match="T_rig_board"):
        TableBoard(BOARD, np.eye(4) * 2.0)
    with pytest.raises(ValueError, match="face_height_m"):
        TableBoard.flat(BOARD, (0.0, 0.0), face_height_m=0.0)
    with pytest.raises(ValueError, match="arm"):
        TableBoard.for_arm(BOARD, "middle")
    with pytest.raises(ValueError, match="texture_ppm"):
        TableBoard.flat(BOARD, (0.0, 0.0)).__class__(BOARD, np.eye(4), texture_ppm=1e5)


def test_the_scene_compiles_with_a_table_board_and_a_gripper_board() -> None:
    table = TableBoard.for_arm(BOARD, "left")
    mount = BoardMount.beside_tcp(BOARD, "right")
    xml = build_mjcf(RIG, board_mount=mount, table_board=table)
    model = compile_scene(xml, assets={**mount.assets(), **table.assets()})
    assert model.geom("table_calibration_board").contype == 0
    assert model.geom("right_calibration_board").conaffinity == 0
    assert "table_calibration_board" not in build_mjcf(RIG)
