"""World model v2's tracked objects: estimated from sim frames, caught, carried, let go, drawn and erased."""

from __future__ import annotations

import math
from pathlib import Path
from types import SimpleNamespace
from typing import Any, cast

import numpy as np
import pytest

from pilworld.config.rig import RigConfig
from pilworld.perception.colour import segment
from pilworld.perception.silhouette import BowlShape, BoxShape, Pose2D
from pilworld.reference.paper_tasks import task_spec
from pilworld.types import ARM_LAYOUT, HEAD_VIEW
from pilworld.world_model.composite.object_draw import draw_objects, erase_elsewhere
from pilworld.world_model.composite.objects import (
    ObjectScene,
    TrackedObject,
    estimate_scene,
    measured_grip,
    support_top,
)
from simrig.robot import SimRobot
from simrig.tasks import load_task

ROOT = Path(__file__).resolve().parents[4]
SIM_RIG = ROOT / "configs" / "rig" / "sim_dual_ur5e.yaml"
CUBE = BoxShape(0.035)
LEFT_GRIP = ARM_LAYOUT["left"][1]
RIGHT_GRIP = ARM_LAYOUT["right"][1]


@pytest.fixture(scope="module")
def rig() -> RigConfig:
    return RigConfig.load(SIM_RIG)


class PointKinematics:
    """Stand-in kinematics: a 14-d vector's joints 0–2 (left) and 7–9 (right) are the tool points,
    the tool pointing straight down with its closing axis along the rig's y."""

    def tcp_poses(self, q: np.ndarray) -> np.ndarray:
        q = np.asarray(q, np.float64)
        T = np.zeros((*q.shape[:-1], 2, 4, 4))
        T[..., :, :3, :3] = np.diag([1.0, -1.0, -1.0])
        T[..., :, 3, 3] = 1.0
        T[..., 0, :3, 3] = q[..., 0:3]
        T[..., 1, :3, 3] = q[..., 7:10]
        return T


def _point_scene(*objects: TrackedObject) -> ObjectScene:
    arm = SimpleNamespace(gripper=SimpleNamespace(max_opening_m=0.085))
    rig = SimpleNamespace(kinematics=PointKinematics(), arms=SimpleNamespace(left=arm, right=arm))
    return ObjectScene(cast(Any, rig), list(objects))


def _cube(x: float, y: float, z: float = 0.0) -> TrackedObject:
    return TrackedObject("cube", CUBE, np.array([230.0, 210.0, 30.0]), Pose2D(x, y, z))


def _pick_and_place(grasp_xy: tuple[float, float], place_xy: tuple[float, float], *, release_z: float = 0.03):
    """A left-arm chunk (K+1 rows): down onto the grasp point, close, lift, carry, lower, open."""
    rows = []

    def at(x: float, y: float, z: float, grip: float) -> None:
        q = np.zeros(14)
        q[0:3] = (x, y, z)
        q[7:10] = (0.0, -0.4, 0.2)  # the right tool far away
        q[LEFT_GRIP], q[RIGHT_GRIP] = grip, 1.0
        rows.append(q)

    gx, gy = grasp_xy
    px, py = place_xy
    at(gx, gy, 0.10, 1.0)
    at(gx, gy, 0.022, 1.0)
    for g in (0.8, 0.6, 0.4, 0.2, 0.0):  # the fingers close (the command runs past the object's width)
        at(gx, gy, 0.022, g)
    at(gx, gy, 0.12, 0.0)
    at(px, py, 0.12, 0.0)
    at(px, py, release_z, 0.0)
    for g in (0.5, 1.0):
        at(px, py, release_z, g)
    at(px, py, 0.12, 1.0)
    seq = np.asarray(rows)
    return seq, seq[1:].copy()


def test_a_caught_cube_is_carried_and_falls_where_it_is_let_go() -> None:
    cube = _cube(0.05, 0.10)
    scene = _point_scene(cube)
    seq, commanded = _pick_and_place((0.055, 0.10), (0.15, -0.05))
    frames, grips, moved = scene.advance(seq, commanded)
    assert moved == {"cube"}
    width = measured_grip(cube, 0.085)
    assert width == pytest.approx(0.035 / 0.085)
    # Held from the closing on: the measured grip stops at the cube's width, never at the closed command.
    assert grips[:, 0].min() == pytest.approx(width)
    lifted = frames[6][0]
    assert lifted.z > 0.08 and lifted.x == pytest.approx(0.05, abs=1e-9)  # its offset across the pads is kept
    final = frames[-1][0]
    assert cube.held_by is None
    assert (final.x, final.y, final.z) == pytest.approx((0.145, -0.05, 0.0), abs=1e-6)  # dropped onto the table
    assert grips[-1, 0] == pytest.approx(1.0)


def test_the_pads_centre_a_cube_along_the_closing_axis() -> None:
    cube = _cube(0.05, 0.11)  # 1 cm off the tool along the closing axis (the rig's y here)
    scene = _point_scene(cube)
    seq, commanded = _pick_and_place((0.05, 0.10), (0.15, -0.05))
    frames, _, _ = scene.advance(seq, commanded)
    assert frames[6][0].y == pytest.approx(0.10, abs=1e-9)


def test_fingers_that_close_beside_a_cube_catch_nothing() -> None:
    cube = _cube(0.05, 0.10)
    scene = _point_scene(cube)
    seq, commanded = _pick_and_place((0.05 + 0.035, 0.10), (0.15, -0.05))  # a cube's width off, across the pads
    frames, grips, moved = scene.advance(seq, commanded)
    assert moved == set()
    assert all(f[0] == cube.pose for f in frames)
    assert grips[:, 0].min() == 0.0  # closed on air


def test_fingers_above_a_cube_catch_nothing() -> None:
    scene = _point_scene(_cube(0.05, 0.10))
    seq, commanded = _pick_and_place((0.05, 0.10), (0.15, -0.05))
    seq[1:7, 2] = 0.08  # closing 8 cm up
    assert scene.advance(seq, commanded)[2] == set()


def test_a_cube_let_go_over_another_lands_on_it() -> None:
    below = TrackedObject("block", BoxShape(0.04), np.array([200.0, 40.0, 40.0]), Pose2D(0.15, -0.05, 0.0))
    cube = _cube(0.05, 0.10)
    scene = _point_scene(cube, below)
    seq, commanded = _pick_and_place((0.05, 0.10), (0.155, -0.05), release_z=0.09)
    frames, _, _ = scene.advance(seq, commanded)
    assert frames[-1][0].z == pytest.approx(0.04)
    off = TrackedObject("cube", CUBE, cube.colour, Pose2D(0.15 + 0.03, -0.05, 0.1))
    assert support_top(off, below) is None  # its centre beyond the top face: it tips off


def test_nested_bowls_rest_where_the_simulator_puts_them() -> None:
    spec = task_spec("stack_bowls")
    large, medium = (spec.object(b) for b in ("bowl_large", "bowl_medium"))
    lo = TrackedObject(large.name, large.shape, np.zeros(3), Pose2D(0.15, 0.0, 0.0))
    up = TrackedObject(medium.name, medium.shape, np.zeros(3), Pose2D(0.15, 0.0, 0.05))
    assert support_top(up, lo) == pytest.approx(load_task("stack_bowls").done_heights()["bowl_medium"], abs=1e-9)


@pytest.mark.parametrize(("task", "subtask"), [("sort_cubes", 0), ("stack_blocks", 1), ("stack_bowls", 1)])
def test_objects_are_found_where_the_simulator_has_them(rig: RigConfig, task: str, subtask: int) -> None:
    with SimRobot(rig, task) as sim:
        sim.reset(seed=1_000_000, subtask=subtask, history=0)
        obs = sim.observe()
        truth = sim.object_poses()
    scene = estimate_scene(rig, task_spec(task).instruction, dict(obs.images), obs.state)
    assert scene is not None
    assert {o.name for o in scene.objects} == set(truth)
    for o in scene.objects:
        t = truth[o.name]
        # underside height: the simulator's pose is the body centre (a box) or its underside (a bowl)
        z = t.position[2] - (o.shape.edge / 2 if isinstance(o.shape, BoxShape) else 0.0)
        assert math.hypot(o.pose.x - t.position[0], o.pose.y - t.position[1]) < 0.012, o.name
        assert o.pose.z == pytest.approx(z, abs=0.006), o.name
        assert o.held_by is None


def test_an_unknown_task_is_not_tracked(rig: RigConfig) -> None:
    images = {v: np.zeros((128, 128, 3), np.uint8) for v in rig.cameras}
    assert estimate_scene(rig, "fold the towel", images, np.zeros(14)) is None


def test_a_drawn_cube_has_its_colour_and_hides_behind_a_nearer_robot(rig: RigConfig) -> None:
    spec = task_spec("sort_cubes")
    obj = spec.objects[0]
    cam = rig.head_camera_model
    image = np.full((128, 128, 3), 180, np.uint8)
    colour = np.asarray(obj.colour.rgb) * 230.0
    pose = Pose2D(0.0, 0.0, 0.0)
    drawn, masks = draw_objects(image, cam, [(obj.shape, pose, colour)], np.zeros((128, 128), np.float32))
    seen = segment(drawn, [obj.colour])[obj.name]
    assert masks[0].sum() >= 6 and (seen & masks[0]).sum() >= 0.8 * masks[0].sum()
    near = np.where(masks[0], 0.01, 0.0).astype(np.float32)  # a robot in front of every pixel of it
    hidden, masks2 = draw_objects(image, cam, [(obj.shape, pose, colour)], near)
    assert masks2[0].sum() == 0 and np.array_equal(hidden, image)
    bowl = task_spec("stack_bowls").objects[0]
    assert isinstance(bowl.shape, BowlShape)
    _, bowl_masks = draw_objects(image, cam, [(bowl.shape, pose, colour)], np.zeros((128, 128), np.float32))
    assert bowl_masks[0].sum() > masks[0].sum()


def _draw_full_frame(image: np.ndarray, camera: Any, objects: Any, robot_depth: np.ndarray) -> Any:
    """draw_objects as it was first written: every face rasterised over the whole frame (the reference)."""
    import cv2

    from pilworld.world_model.composite.object_draw import _SHIFT, _polygons

    h, w = image.shape[:2]
    out = image.copy()
    zbuf = np.where(robot_depth > 0, robot_depth, np.inf).astype(np.float64)
    parts = [(d, i, uv, rgb) for i, (sh, po, co) in enumerate(objects) for d, uv, rgb in _polygons(camera, sh, po, co)]
    masks = {i: np.zeros((h, w), bool) for i in range(len(objects))}
    for depth, index, uv, rgb in sorted(parts, key=lambda p: -p[0]):
        if not np.all(np.isfinite(uv)) or np.abs(uv).max() > 8 * max(h, w):
            continue
        canvas = np.zeros((h, w), np.uint8)
        cv2.fillConvexPoly(canvas, np.round(uv * (1 << _SHIFT)).astype(np.int32), 1, lineType=cv2.LINE_8, shift=_SHIFT)
        px = (canvas > 0) & (depth < zbuf)
        out[px] = np.clip(rgb, 0, 255).astype(np.uint8)
        zbuf[px] = depth
        for m in masks.values():
            m[px] = False
        masks[index] |= px
    return out, masks


def test_drawing_in_windows_equals_drawing_over_the_frame(rig: RigConfig) -> None:
    rng = np.random.default_rng(3)
    cam = rig.head_camera_model
    shapes = [o.shape for t in ("sort_cubes", "stack_blocks", "stack_bowls") for o in task_spec(t).objects]
    drawn = at_border = 0
    for trial in range(40):
        objs = [
            (
                shapes[int(rng.integers(len(shapes)))],
                # some well inside the view, some across its border, a few off it
                Pose2D(*rng.uniform([-0.5, -0.45, 0.0, -math.pi], [0.5, 0.35, 0.2, math.pi]).tolist()),
                rng.uniform(0, 255, 3),
            )
            for _ in range(int(rng.integers(1, 5)))
        ]
        image = rng.integers(0, 256, (128, 128, 3), dtype=np.uint8)
        robot = np.where(rng.random((128, 128)) < 0.3, rng.uniform(0.2, 1.5, (128, 128)), 0).astype(np.float32)
        got, got_masks = draw_objects(image, cam, objs, robot)
        want, want_masks = _draw_full_frame(image, cam, objs, robot)
        assert np.array_equal(got, want), trial
        assert all(np.array_equal(got_masks[i], want_masks[i]) for i in want_masks), trial
        union = np.any([m for m in want_masks.values()], axis=0)
        drawn += int(union.sum())
        at_border += int(union[[0, -1]].any() or union[:, [0, -1]].any())
    assert drawn > 2000 and at_border >= 3  # the comparison saw objects, some of them cut by the frame


def test_a_ghost_is_erased_but_the_object_and_the_robot_are_kept(rig: RigConfig) -> None:
    obj = task_spec("sort_cubes").objects[0]
    image = np.full((32, 32, 3), 180, np.uint8)
    rgb = (np.asarray(obj.colour.rgb) * 230.0).astype(np.uint8)
    image[2:6, 2:6] = rgb  # the ghost where it was
    image[20:24, 20:24] = rgb  # where it is now
    image[10:14, 10:14] = rgb  # under the robot's mask: not ours to change
    keep = np.zeros((32, 32), bool)
    keep[20:24, 20:24] = True
    robot = np.zeros((32, 32), bool)
    robot[10:14, 10:14] = True
    background = np.full((32, 32, 3), 90, np.uint8)
    out = erase_elsewhere(image, [obj.colour], [keep], robot, background)
    assert (out[2:6, 2:6] == 90).all()
    assert (out[20:24, 20:24] == rgb).all() and (out[10:14, 10:14] == rgb).all()
    assert HEAD_VIEW in rig.cameras
