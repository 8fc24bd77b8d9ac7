"""The mujoco robot-render backend against the simulator's own full-scene segmentation and against ray casts."""

from __future__ import annotations

from collections.abc import Callable, Iterator
from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from pilworld.bench.robot_render import sim_robot_parts
from pilworld.config.rig import RigConfig
from pilworld.control_video.cameras import RigCameras, ViewCamera
from pilworld.control_video.robot_model import HIDDEN_GROUP, PART_IDS, RobotModel
from pilworld.control_video.robot_render import make_robot_renderer
from pilworld.control_video.robot_render_mujoco import MujocoRobotRenderer
from simrig.gl import mujoco
from simrig.poses import HOME_Q14

RIGS = Path(__file__).resolve().parents[3] / "configs" / "rig"
SIM_RIG, REAL_RIG = RIGS / "sim_dual_ur5e.yaml", RIGS / "real_dual_ur5e.yaml"
# Both arms reaching a little forward and down from HOME (shoulder lift +0.2 rad), grippers half
# open, still 6 cm above the table beside the workspace: in view of the head camera, hidden by nothing.
REACH = HOME_Q14.copy()
REACH[[1, 8]] += 0.2
REACH[[6, 13]] = (0.3, 0.8)


@pytest.fixture(scope="module")
def rig() -> RigConfig:
    return RigConfig.load(SIM_RIG)


@pytest.fixture(scope="module")
def robot(rig: RigConfig) -> RobotModel:
    return RobotModel.from_rig(rig)


@pytest.fixture(scope="module")
def renderer(rig: RigConfig, robot: RobotModel) -> Iterator[MujocoRobotRenderer]:
    r = make_robot_renderer(rig, "mujoco", robot=robot)
    assert isinstance(r, MujocoRobotRenderer)
    yield r
    r.close()


def _iou(a: np.ndarray[Any, Any], b: np.ndarray[Any, Any]) -> float:
    return float((a & b).sum() / max((a | b).sum(), 1))


def test_robot_only_render_equals_full_scene_where_nothing_occludes(
    renderer: MujocoRobotRenderer, robots: Callable[[str], Any]
) -> None:
    sim = robots("sort_cubes")
    sim.reset(seed=3, history=0)
    q = np.stack([HOME_Q14, REACH])
    out = renderer.render(q)
    gt, gt_depth = sim_robot_parts(sim, q)
    assert gt_depth is not None and out.depth is not None
    for v in renderer.cameras.names:
        assert out.parts[v].shape == gt[v].shape == (2, 128, 128)
        for i in range(2):
            assert gt[v][i].sum() > 0, (v, i)
            assert _iou(out.parts[v][i] > 0, gt[v][i] > 0) >= 0.99, (v, i)
            assert np.mean(out.parts[v][i] == gt[v][i]) >= 0.995, (v, i)  # the same part ids too
        both = (out.parts[v] > 0) & (gt[v] > 0)
        assert np.median(np.abs(out.depth[v] - gt_depth[v])[both]) < 1e-3


def test_part_ids_per_view(renderer: MujocoRobotRenderer) -> None:
    out = renderer.render(REACH, depth=False, shaded=False)
    assert out.depth is None and out.shaded is None
    left, right = set(np.unique(out.parts["cam_left_wrist"])), set(np.unique(out.parts["cam_right_wrist"]))
    assert PART_IDS["left_fingers"] in left and PART_IDS["right_fingers"] not in left
    assert PART_IDS["right_fingers"] in right and PART_IDS["left_fingers"] not in right
    assert {PART_IDS["left_arm"], PART_IDS["right_arm"]} <= set(np.unique(out.parts["cam_high"]))


def _ray_parts_depth(
    robot: RobotModel, cameras: RigCameras, q: np.ndarray[Any, Any], step: int = 3
) -> dict[str, tuple[np.ndarray[Any, Any], np.ndarray[Any, Any], np.ndarray[Any, Any]]]:
    """Per view: pixels on a grid, the part id and the camera-frame Z that ``mj_ray`` finds through each."""
    m = robot.model
    d = mujoco.MjData(m)
    d.qpos[:] = robot.qpos(q)
    mujoco.mj_kinematics(m, d)
    lut = np.zeros(m.ngeom, np.uint8)
    lut[robot.geom_ids] = robot.geom_part
    groups = np.ones(6, np.uint8)
    groups[HIDDEN_GROUP] = 0
    gid = np.zeros(1, np.int32)
    out = {}
    for v in cameras.views:
        T = cameras.poses(q)[v.name]
        R, centre = T[:3, :3], -T[:3, :3].T @ T[:3, 3]
        vv, uu = np.mgrid[0 : v.model.height : step, 0 : v.model.width : step]
        uv = np.stack([uu.ravel(), vv.ravel()], 1)
        rays = v.model.unproject(uv.astype(np.float64))
        parts, z = np.zeros(len(uv), np.uint8), np.zeros(len(uv))
        for k, r in enumerate(rays):
            dist = mujoco.mj_ray(m, d, centre, R.T @ r, groups, 1, -1, gid)
            if dist >= 0:
                parts[k], z[k] = lut[gid[0]], dist * r[2]
        out[v.name] = (uv, parts, z)
    return out


@pytest.mark.parametrize("off_centre", [False, True])
def test_parts_and_depth_match_ray_casts_through_the_camera_model(
    rig: RigConfig, robot: RobotModel, off_centre: bool
) -> None:
    """Depth is camera-frame Z (not the distance along the ray), and any undistorted K is reproduced."""
    cameras = RigCameras.from_rig(rig)
    if off_centre:  # non-square pixels, an off-centre principal point and a wider image
        views = []
        for v in cameras.views:
            K = v.model.K.copy()
            K[0, 0] *= 1.1
            K[0, 2] += 9.0
            K[1, 2] -= 5.0
            views.append(ViewCamera(v.name, replace(v.model, K=K, width=160), v.arm))
        cameras = RigCameras(cameras.kinematics, tuple(views))
    with MujocoRobotRenderer(robot, cameras) as r:
        out = r.render(REACH)
    assert out.depth is not None
    for view, (uv, parts, z) in _ray_parts_depth(robot, cameras, REACH).items():
        rendered = out.parts[view][0, uv[:, 1], uv[:, 0]]
        assert (parts > 0).sum() > 50, view
        assert np.mean(rendered == parts) >= 0.995, view
        both = (parts > 0) & (rendered > 0)
        err = np.abs(out.depth[view][0, uv[:, 1], uv[:, 0]][both] - z[both])
        assert np.median(err) < 1e-3 and np.percentile(err, 90) < 2e-3, view


def test_shaded_is_black_off_the_robot(renderer: MujocoRobotRenderer) -> None:
    out = renderer.render(HOME_Q14[None], depth=True, shaded=True)
    assert out.shaded is not None and out.depth is not None
    for v in renderer.cameras.names:
        mask = out.parts[v][0] > 0
        assert out.shaded[v].shape == (1, 128, 128, 3) and out.shaded[v].dtype == np.uint8
        assert not out.shaded[v][0][~mask].any()
        assert out.shaded[v][0][mask].mean() > 10
        assert np.all(out.depth[v][0][~mask] == 0) and np.all(out.depth[v][0][mask] > 0.01)


def test_bad_input(renderer: MujocoRobotRenderer, robot: RobotModel) -> None:
    with pytest.raises(ValueError, match="q14"):
        renderer.render(np.zeros(13))
    bad = HOME_Q14.copy()
    bad[0] = np.nan
    with pytest.raises(ValueError, match="q14"):
        renderer.render(bad)
    # A calibrated real head camera has lens distortion: MuJoCo cannot draw it, and says so.
    real = RigCameras.from_rig(RigConfig.load(REAL_RIG))
    with pytest.raises(ValueError, match="distortion"):
        MujocoRobotRenderer(robot, real)
