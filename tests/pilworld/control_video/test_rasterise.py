"""The analytic robot renderer against MuJoCo's own (robot-only, no table): masks, part ids and depth on
random configurations; a camera inside a geom; geoms crossing the near plane; lens distortion; bad input."""

from __future__ import annotations

import copy
import dataclasses
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from calib.camera_model import CameraModel
from pilworld.config.rig import RigConfig
from pilworld.control_video.cameras import RigCameras, ViewCamera
from pilworld.control_video.examples import HOME_Q14, random_chunks
from pilworld.control_video.rasterise import AnalyticRobotRenderer
from pilworld.control_video.robot_model import BOX, HIDDEN_GROUP, RobotModel
from pilworld.control_video.robot_render import RobotRender, make_robot_renderer
from pilworld.control_video.robot_render_mujoco import MujocoRobotRenderer
from pilworld.geometry import invert_transform
from pilworld.types import HEAD_VIEW

RIGS = Path(__file__).resolve().parents[3] / "configs" / "rig"
Arr = np.ndarray[Any, Any]


@pytest.fixture(scope="module")
def rig() -> RigConfig:
    return RigConfig.load(RIGS / "sim_dual_ur5e.yaml")


@pytest.fixture(scope="module")
def robot(rig: RigConfig) -> RobotModel:
    return RobotModel.from_rig(rig)


@pytest.fixture(scope="module")
def analytic(rig: RigConfig, robot: RobotModel) -> AnalyticRobotRenderer:
    r = make_robot_renderer(rig, robot=robot)
    assert isinstance(r, AnalyticRobotRenderer)
    return r


@pytest.fixture(scope="module")
def mujoco_r(rig: RigConfig, robot: RobotModel) -> Iterator[MujocoRobotRenderer]:
    r = make_robot_renderer(rig, "mujoco", robot=robot)
    assert isinstance(r, MujocoRobotRenderer)
    yield r
    r.close()


def _iou(a: Arr, b: Arr) -> float:
    return float((a & b).sum() / max(int((a | b).sum()), 1))


def _compare(a: RobotRender, m: RobotRender, view: str) -> tuple[list[float], float, float]:
    """Per-frame mask IoU, part-id agreement on the union and median |Δdepth| on common pixels."""
    pa, pm = a.parts[view], m.parts[view]
    A, M = pa > 0, pm > 0
    ious = [_iou(A[i], M[i]) for i in range(len(pa))]
    union = A | M
    agree = float(((pa == pm) & union).sum() / max(int(union.sum()), 1))
    assert a.depth is not None and m.depth is not None
    common = A & M
    dz = float(np.median(np.abs(a.depth[view][common] - m.depth[view][common])))
    return ious, agree, dz


def test_analytic_matches_mujoco_on_random_configurations(
    analytic: AnalyticRobotRenderer, mujoco_r: MujocoRobotRenderer
) -> None:
    q = random_chunks(8, seed=11)[:, 25].astype(np.float64)  # 8 configurations, grips anywhere in [0, 1]
    a, m = analytic.render(q), mujoco_r.render(q, shaded=False)
    for view in a.views:
        ious, agree, dz = _compare(a, m, view)
        assert np.mean(ious) >= 0.95 and min(ious) >= 0.93, (view, ious)
        assert agree >= 0.90, (view, agree)
        assert dz <= 0.005, (view, dz)
        assert np.all(m.parts[view].reshape(8, -1).max(axis=1) > 0), view  # the robot is in every view


def _without_geom(robot: RobotModel, g: int) -> RobotModel:
    """The robot without its ``g``-th geom: not a robot geom (analytic), hidden (MuJoCo)."""
    model = copy.deepcopy(robot.model)
    model.geom_group[robot.geom_ids[g]] = HIDDEN_GROUP
    keep = np.arange(robot.geom_ids.size) != g
    return dataclasses.replace(robot, model=model, geom_ids=robot.geom_ids[keep], geom_part=robot.geom_part[keep])


def _head_at(rig: RigConfig, camera: CameraModel) -> RigCameras:
    return RigCameras(rig.kinematics, (ViewCamera(HEAD_VIEW, camera, None),))


def test_a_camera_inside_a_geom_sees_nothing_of_it(rig: RigConfig, robot: RobotModel) -> None:
    q = HOME_Q14.astype(np.float64)
    pos, _ = robot.geom_poses(q)
    g = int(np.argmax(robot.geom_size[:, 0] * (robot.geom_type != BOX)))  # the thickest round link
    target = rig.kinematics.gripper_points(q)[1]  # the right TCP, across the table
    inside = CameraModel.look_at(pos[0, g], target, [0.0, 0.0, 1.0], 70.0, 128, 128)
    fwd = target - pos[0, g]
    fwd /= np.linalg.norm(fwd)
    outside = CameraModel.look_at(pos[0, g] - 0.3 * fwd, target, [0.0, 0.0, 1.0], 70.0, 128, 128)
    cut = _without_geom(robot, g)
    for cam, sees_it in ((inside, False), (outside, True)):
        cams = _head_at(rig, cam)
        full = make_robot_renderer(rig, robot=robot, cameras=cams).render(q, shaded=False)
        less = make_robot_renderer(rig, robot=cut, cameras=cams).render(q, shaded=False)
        same = np.array_equal(full.parts[HEAD_VIEW], less.parts[HEAD_VIEW])
        assert same != sees_it, ("inside" if not sees_it else "outside", g)
        assert full.mask[HEAD_VIEW].any()  # the other arm is in view either way
        with MujocoRobotRenderer(robot, cams) as ref:
            m = ref.render(q, shaded=False)
        ious, agree, _ = _compare(full, m, HEAD_VIEW)
        assert ious[0] >= 0.95 and agree >= 0.9, (sees_it, ious, agree)


def _crossing_boxes(robot: RobotModel, cams: RigCameras, view: str, q: Arr, near: float) -> list[int]:
    """Robot boxes with corners on both sides of the near plane in ``view`` at ``q``."""
    pos, rot = robot.geom_poses(q)
    T = cams.poses(q)[view][0]
    out = []
    corners = np.array([[x, y, z] for x in (-1, 1) for y in (-1, 1) for z in (-1, 1)], dtype=np.float64)
    for g in np.flatnonzero(robot.geom_type == BOX):
        world = pos[0, g] + (corners * robot.geom_size[g]) @ rot[0, g].T
        z = world @ T[2, :3] + T[2, 3]
        if z.min() < near < z.max():
            out.append(int(g))
    return out


@pytest.mark.parametrize("shift_m", [0.0, 0.01])
def test_geoms_crossing_the_near_plane_are_clipped_like_mujoco(
    rig: RigConfig, robot: RobotModel, analytic: AnalyticRobotRenderer, shift_m: float
) -> None:
    """At HOME the left palm crosses the left wrist camera's near plane; 1 cm closer it crosses deeper."""
    base = RigCameras.from_rig(rig)
    views = []
    for v in base.views:
        T = v.model.T_cam_base.copy()
        if v.arm is not None:
            T[2, 3] -= shift_m  # the camera 1 cm further along its optical axis, towards its gripper
        views.append(ViewCamera(v.name, v.model.with_pose(T), v.arm))
    cams = RigCameras(base.kinematics, tuple(views))
    q = np.stack([HOME_Q14, HOME_Q14]).astype(np.float64)
    q[1, [6, 13]] = 0.0  # and with the grippers closed
    crossing = _crossing_boxes(robot, cams, "cam_left_wrist", q[:1], analytic.near)
    assert crossing, "no box crosses the near plane: the test does not test clipping"
    a = make_robot_renderer(rig, robot=robot, cameras=cams).render(q, shaded=False)
    with MujocoRobotRenderer(robot, cams) as ref:
        m = ref.render(q, shaded=False)
    cut = robot
    for g in sorted(crossing, reverse=True):
        cut = _without_geom(cut, g)
    b = make_robot_renderer(rig, robot=cut, cameras=cams).render(q, shaded=False)
    clipped_px = (a.mask["cam_left_wrist"] & ~b.mask["cam_left_wrist"]).sum(axis=(1, 2))
    assert np.all(clipped_px > 0.1 * a.mask["cam_left_wrist"].sum(axis=(1, 2))), clipped_px  # a large share
    for view in ("cam_left_wrist", "cam_right_wrist"):
        ious, agree, dz = _compare(a, m, view)
        assert min(ious) >= 0.95 and agree >= 0.9 and dz <= 0.005, (view, ious, agree, dz)
        assert a.depth is not None
        near_px = a.depth[view][a.mask[view]]
        assert near_px.min() >= analytic.near - 1e-6  # nothing is drawn in front of the near plane


@pytest.fixture(scope="module")
def real_rig() -> RigConfig:
    return RigConfig.load(RIGS / "real_dual_ur5e.yaml")


def test_a_distorted_head_camera_renders_where_it_projects(real_rig: RigConfig) -> None:
    cams = RigCameras.from_rig(real_rig)
    head = cams.view(HEAD_VIEW).model
    assert head.dist.size and np.any(head.dist != 0), "the real rig's example head camera should be distorted"
    robot = RobotModel.from_rig(real_rig)
    assert real_rig.hardware is not None
    q: Arr = np.stack([np.asarray(real_rig.hardware.start_pose, dtype=np.float64), HOME_Q14])
    strong = dataclasses.replace(head, dist=np.array([-0.25, 0.06, 0.001, -0.001, 0.0]))
    pinhole = dataclasses.replace(head, dist=np.zeros(0))
    pos, _ = robot.geom_poses(q)
    pin_mask = make_robot_renderer(real_rig, robot=robot, cameras=_head_at(real_rig, pinhole)).render(q).mask
    for cam, moved_px in ((head, 0.5), (strong, 8.0)):
        render = make_robot_renderer(real_rig, robot=robot, cameras=_head_at(real_rig, cam)).render(q)
        mask = render.mask[HEAD_VIEW]
        assert mask.any(axis=(1, 2)).all()
        for i in range(len(q)):
            # Every geom's centre lies inside the geom, so it projects onto the robot.
            uv, vis = cam.project(pos[i])
            assert vis.sum() >= 10
            px = np.rint(uv[vis]).astype(int)
            assert mask[i][px[:, 1], px[:, 0]].all(), (cam.dist.tolist(), i)
            # ...where the pinhole projection is not, far enough for the test to tell them apart.
            uvp, _ = pinhole.project(pos[i])
            assert np.linalg.norm(uv - uvp, axis=-1)[vis].max() > moved_px
            # Each robot pixel's ray hits the robot in the pinhole render (the remap is the lens).
            v, u = np.nonzero(mask[i])
            rays = cam.unproject(np.stack([u, v], axis=-1).astype(np.float64))
            K = pinhole.K
            pu = np.rint(K[0, 0] * rays[:, 0] / rays[:, 2] + K[0, 2]).astype(int)
            pv = np.rint(K[1, 1] * rays[:, 1] / rays[:, 2] + K[1, 2]).astype(int)
            ok = (pu >= 0) & (pu < cam.width) & (pv >= 0) & (pv < cam.height)
            assert pin_mask[HEAD_VIEW][i][pv[ok], pu[ok]].mean() > 0.995
        assert not np.array_equal(mask, pin_mask[HEAD_VIEW])
    # MuJoCo cannot draw a lens: refused in one line that names the camera.
    with pytest.raises(ValueError, match=r"^camera 'cam_high': the mujoco robot renderer draws undistorted"):
        make_robot_renderer(real_rig, "mujoco", robot=robot)


@pytest.mark.parametrize(
    ("value", "pattern"),
    [
        (np.zeros((3, 13)), r"^q14: expected joint vectors \(N, 14\)"),
        (np.zeros((2, 3, 14)), r"^q14: expected joint vectors"),
        (np.zeros(13), r"^q14: expected"),
    ],
)
def test_bad_joint_vectors_are_refused(analytic: AnalyticRobotRenderer, value: Arr, pattern: str) -> None:
    with pytest.raises(ValueError, match=pattern) as info:
        analytic.render(value)
    assert "\n" not in str(info.value)


def test_non_finite_joints_are_refused(analytic: AnalyticRobotRenderer) -> None:
    q = np.stack([HOME_Q14, HOME_Q14]).astype(np.float64)
    q[1, 4] = np.nan
    with pytest.raises(ValueError, match=r"^q14: contains non-finite values \(first at \[frame, index\] \[1, 4\]\)"):
        analytic.render(q)
    with pytest.raises(ValueError, match=r"^q14: "):
        analytic.render(np.full(14, np.inf))


def test_wrist_camera_pose_is_its_mount_on_the_tcp(rig: RigConfig) -> None:
    """The renderer's wrist poses are T_cam_tcp · T_tcp_rig (what the near-plane test moves)."""
    cams = RigCameras.from_rig(rig)
    q = HOME_Q14.astype(np.float64)
    tcp = rig.kinematics.tcp_poses(q)
    for i, name in enumerate(("cam_left_wrist", "cam_right_wrist")):
        T = cams.poses(q)[name]
        np.testing.assert_allclose(T, cams.view(name).model.T_cam_base @ invert_transform(tcp[i]), atol=1e-12)
