"""The board pose planner: reachable, visible, diverse poses; degenerate settings are refused before moving."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from calib.board import ChArUcoBoard
from calib.handeye import DegenerateMotionError
from calib.rotations import rotation_angle
from pilworld.calibration.occlusion import arm_capsules, segment_distances
from pilworld.calibration.plan import PlannerSettings, PosePlan, plan_board_poses
from pilworld.config.rig import RigConfig
from pilworld.types import ARM_LAYOUT
from simrig.board_mount import BoardMount
from simrig.poses import HOME_Q14

ROOT = Path(__file__).resolve().parents[3]
SIM = ROOT / "configs" / "rig" / "sim_dual_ur5e.yaml"
A4 = ROOT / "configs" / "board" / "charuco_7x5_a4.yaml"


@pytest.fixture(scope="module")
def rig() -> RigConfig:
    return RigConfig.load(SIM)


@pytest.fixture(scope="module")
def board() -> ChArUcoBoard:
    return ChArUcoBoard.from_yaml(A4)


def _plan(rig: RigConfig, board: ChArUcoBoard, arm: str, settings: PlannerSettings, seed: int = 0) -> PosePlan:
    mount = BoardMount.beside_tcp(board, arm)
    return plan_board_poses(
        rig.kinematics, rig.head_camera_model, board, mount.T_tcp_board, arm, HOME_Q14, settings, seed
    )


@pytest.mark.parametrize("arm", ["left", "right"])
def test_default_plan_is_reachable_visible_and_diverse(rig: RigConfig, board: ChArUcoBoard, arm: str) -> None:
    mount = BoardMount.beside_tcp(board, arm)
    camera = rig.head_camera_model
    plan = plan_board_poses(rig.kinematics, camera, board, mount.T_tcp_board, arm, HOME_Q14, seed=0)
    print(plan.summary(), plan.rejected)
    assert len(plan.poses) == 20 and plan.feasible >= 20
    assert plan.motion.rotation_span_deg >= 40.0
    assert plan.motion.axis_spread >= 0.3  # rotations about many axes, far from the 0.1 refusal limit
    arm_mount = getattr(rig.kinematics, arm)
    lower, upper = arm_mount.dh.lower_limits, arm_mount.dh.upper_limits
    states = plan.states(HOME_Q14)
    other = "right" if arm == "left" else "left"
    assert np.array_equal(states[:, ARM_LAYOUT[other][0]], np.repeat(HOME_Q14[None, ARM_LAYOUT[other][0]], 20, axis=0))
    tilts = []
    for pose, state in zip(plan.poses, states, strict=True):
        assert np.all(pose.q >= lower) and np.all(pose.q <= upper)
        assert np.allclose(arm_mount.tcp_pose(pose.q), pose.T_rig_tcp, atol=1e-9)  # IK reaches it exactly
        assert np.allclose(pose.T_rig_tcp @ mount.T_tcp_board, pose.T_rig_board, atol=1e-9)
        T = pose.T_rig_board
        _, visible = camera.project(mount.page_corners_tcp() @ pose.T_rig_tcp[:3, :3].T + pose.T_rig_tcp[:3, 3])
        assert visible.all()
        # The printed face looks at the camera, 15-35° off the line of sight.
        centre = T[:3, :3] @ np.array([board.size_m[0] / 2, board.size_m[1] / 2, 0.0]) + T[:3, 3]
        sight = camera.camera_center_in_base() - centre
        tilts.append(math.degrees(math.acos(float(-T[:3, 2] @ sight / np.linalg.norm(sight)))))
        # No line of sight from the camera to a corner passes through an arm.
        corners = board.corner_points() @ T[:3, :3].T + T[:3, 3]
        caps = arm_capsules(arm_mount, pose.q) + arm_capsules(getattr(rig.kinematics, other), HOME_Q14[:6])
        eye = np.broadcast_to(camera.camera_center_in_base(), corners.shape)
        assert np.all(segment_distances(eye, corners, caps.start, caps.end) > caps.radius)
        assert state[ARM_LAYOUT[arm][0]] == pytest.approx(pose.q)
    assert min(tilts) >= 14.9 and max(tilts) <= 35.1
    # Consecutive poses are ordered for short moves: no pose is revisited and the first is near the start.
    angles = [rotation_angle(a.T_rig_board[:3, :3] @ b.T_rig_board[:3, :3].T) for a in plan.poses for b in plan.poses]
    assert sorted(angles)[20] > math.radians(1.0)  # 20 zeros on the diagonal, then distinct poses


def test_plans_are_seeded(rig: RigConfig, board: ChArUcoBoard) -> None:
    settings = PlannerSettings(poses=5, candidates=400)
    a, b, c = (_plan(rig, board, "left", settings, seed) for seed in (4, 4, 5))
    qa, qb, qc = (np.array([p.q for p in plan.poses]) for plan in (a, b, c))
    assert np.array_equal(qa, qb)
    assert not np.array_equal(qa, qc)


def test_small_rotations_are_refused_before_the_robot_moves(rig: RigConfig, board: ChArUcoBoard) -> None:
    settings = PlannerSettings(poses=10, candidates=600, tilt_deg=(0.0, 1.5), yaw_deg=(-1.0, 1.0), face_camera=False)
    with pytest.raises(DegenerateMotionError, match=r"left arm.*rotation span too small"):
        _plan(rig, board, "left", settings)


def test_a_single_rotation_axis_is_refused(rig: RigConfig, board: ChArUcoBoard) -> None:
    settings = PlannerSettings(
        poses=10, tilt_deg=(-30.0, 30.0), tilt_axis_deg=(0.0, 0.0), yaw_deg=(0.0, 0.0), face_camera=False
    )
    with pytest.raises(DegenerateMotionError, match=r"right arm.*rotations about a single axis"):
        _plan(rig, board, "right", settings)


def test_too_few_poses_are_refused(rig: RigConfig, board: ChArUcoBoard) -> None:
    with pytest.raises(DegenerateMotionError, match=r"too few poses: got 2"):
        _plan(rig, board, "left", PlannerSettings(poses=2, candidates=300))


def test_bad_settings_and_impossible_regions(rig: RigConfig, board: ChArUcoBoard) -> None:
    with pytest.raises(ValueError, match="planner poses"):
        PlannerSettings(poses=0)
    with pytest.raises(ValueError, match="planner tilt_deg"):
        PlannerSettings(tilt_deg=(30.0, 10.0))
    with pytest.raises(ValueError, match="planner image_margin"):
        PlannerSettings(image_margin=0.7)
    with pytest.raises(ValueError, match="arm: expected one of left, right"):
        _plan(rig, board, "middle", PlannerSettings(poses=3))
    far = PlannerSettings(poses=5, candidates=50, region_x=(2.0, 2.5))  # far beyond reach and view
    with pytest.raises(ValueError, match=r"none of 50 candidate board poses is feasible \(not inside the image"):
        _plan(rig, board, "left", far)
