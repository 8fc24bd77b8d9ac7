"""The wrist-camera pose planner: feasible, unoccluded, diverse views of a board on the table."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from calib.board import ChArUcoBoard
from calib.handeye import DegenerateMotionError
from pilworld.calibration.gripper_mask import gripper_boxes_tcp
from pilworld.calibration.gripper_mask import gripper_mask as _gripper_mask
from pilworld.calibration.plan import WristPlannerSettings, plan_wrist_poses
from pilworld.config.rig import RigConfig
from pilworld.geometry import invert_transform
from simrig.poses import HOME_Q14
from simrig.table_board import TableBoard

ROOT = Path(__file__).resolve().parents[3]
RIG = RigConfig.load(ROOT / "configs" / "rig" / "sim_dual_ur5e.yaml")
BOARD = ChArUcoBoard.from_yaml(ROOT / "configs" / "board" / "charuco_7x5_a4.yaml")


@pytest.mark.parametrize("camera", ["cam_left_wrist", "cam_right_wrist"])
def test_planned_views_see_the_whole_board_above_the_gripper(camera: str) -> None:
    arm = RIG.wrist_cameras[camera].arm
    cam = RIG.wrist_camera_model(camera).resized(512, 512)
    table = TableBoard.for_arm(BOARD, arm)
    settings = WristPlannerSettings(poses=12, candidates=800)
    plan = plan_wrist_poses(RIG.kinematics, cam, BOARD, table.T_rig_board, arm, HOME_Q14, settings, seed=3)
    assert plan.arm == arm and len(plan.poses) == 12
    assert plan.motion is not None and plan.motion.rotation_span_deg >= 40.0 and plan.motion.axis_spread >= 0.3
    mount = getattr(RIG.kinematics, arm)
    blocked = _gripper_mask(cam, gripper_boxes_tcp(0.085, 1.0))
    page = table.to_rig(table.page_corners_board())
    for pose in plan.poses:
        assert np.allclose(mount.tcp_pose(pose.q), pose.T_rig_tcp, atol=1e-6)
        assert pose.T_rig_tcp[2, 3] >= 0.10
        T_cam_rig = cam.T_cam_base @ invert_transform(pose.T_rig_tcp)
        uv, visible = cam.with_pose(T_cam_rig).project(page)
        assert visible.all()
        assert uv.min() >= 0.04 * 512 - 1 and uv.max() <= 512 * 0.96
        # The page's corners lie outside the gripper's part of the image.
        iu, iv = ((uv + 0.5) / 8).astype(int).T
        assert not blocked[np.clip(iv, 0, 63), np.clip(iu, 0, 63)].any()
    states = plan.states(HOME_Q14)
    lo, hi = (7, 13) if arm == "left" else (0, 6)  # the other arm holds still
    assert np.allclose(states[:, lo:hi], HOME_Q14[lo:hi])


def test_gripper_mask_covers_the_bottom_of_the_wrist_image() -> None:
    cam = RIG.wrist_camera_model("cam_left_wrist").resized(512, 512)
    mask = _gripper_mask(cam, gripper_boxes_tcp(0.085, 1.0))
    assert mask.shape == (64, 64)
    assert mask[-4:].mean() > 0.9 and mask[:20].mean() == 0.0
    assert len(gripper_boxes_tcp(0.085, 0.0)) == 3


def test_a_planner_that_only_slides_the_camera_is_refused_before_moving() -> None:
    table = TableBoard.for_arm(BOARD, "left")
    cam = RIG.wrist_camera_model("cam_left_wrist")
    settings = WristPlannerSettings(poses=8, candidates=300, tilt_deg=(0.0, 0.0), roll_deg=(0.0, 0.0))
    with pytest.raises(DegenerateMotionError, match="left arm, planned wrist-camera poses: pure translation") as info:
        plan_wrist_poses(RIG.kinematics, cam, BOARD, table.T_rig_board, "left", HOME_Q14, settings)
    assert "add rotations about two different axes" in str(info.value)


def test_bad_settings_name_the_field() -> None:
    with pytest.raises(ValueError, match="distance_m"):
        WristPlannerSettings(distance_m=(0.5, 0.3))
    with pytest.raises(ValueError, match="aim_v"):
        WristPlannerSettings(aim_v=1.2)
    with pytest.raises(ValueError, match="poses"):
        WristPlannerSettings(poses=0)
    table = TableBoard.for_arm(BOARD, "left")
    with pytest.raises(ValueError, match="arm"):
        plan_wrist_poses(RIG.kinematics, RIG.wrist_camera_model("cam_left_wrist"), BOARD, table.T_rig_board, "up",
                         HOME_Q14)  # fmt: skip


def test_an_unreachable_board_reports_why() -> None:
    far = TableBoard.flat(BOARD, (2.0, 2.0))
    cam = RIG.wrist_camera_model("cam_left_wrist")
    with pytest.raises(ValueError, match=r"none of 200 candidate camera poses is feasible.*unreachable"):
        plan_wrist_poses(RIG.kinematics, cam, BOARD, far.T_rig_board, "left", HOME_Q14,
                         WristPlannerSettings(candidates=200))  # fmt: skip
