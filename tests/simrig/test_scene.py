"""The simulated rig's MJCF: the scene agrees with the rig config it is generated from.

* the ``{side}_tcp`` sites sit exactly where ``pilworld.kinematics`` puts the TCPs (acceptance: ≤ 1e-6 m);
* ``cam_high`` renders points where the rig's ``CameraModel`` projects them (≤ 1.5 px at 128×128);
* head cameras MuJoCo cannot render (distortion, off-centre principal point) are refused with the fix;
* task objects validate their dimensions, and every registered task's scene compiles.
"""

from __future__ import annotations

import dataclasses
from pathlib import Path
from typing import Any

import numpy as np
import pytest
import yaml

from calib.camera_model import CameraModel
from pilworld.config.rig import RigConfig
from pilworld.types import LEFT_ARM, RIGHT_ARM
from simrig.gl import make_renderer, mujoco
from simrig.objects import GeomSpec, ObjectSpec, bowl_object, box_object
from simrig.scene import build_mjcf, compile_scene, scene_assets
from simrig.tasks import load_task, packaged_tasks

ROOT = Path(__file__).resolve().parents[2]
SIM = ROOT / "configs" / "rig" / "sim_dual_ur5e.yaml"
EXAMPLE_CAMERA = ROOT / "configs" / "calib" / "head_camera_example.yaml"
SIDES = (("left", LEFT_ARM, 0), ("right", RIGHT_ARM, 1))


@pytest.fixture(scope="module")
def rig() -> RigConfig:
    return RigConfig.load(SIM)


# ---------------------------------------------------------------------- TCP agreement


def test_tcp_sites_match_the_kinematics(rig: RigConfig) -> None:
    model = mujoco.MjModel.from_xml_string(build_mjcf(rig))
    data = mujoco.MjData(model)
    qadr = {side: np.array([model.joint(f"{side}_joint_{i}").qposadr[0] for i in range(1, 7)]) for side, _, _ in SIDES}
    site = {side: model.site(f"{side}_tcp").id for side, _, _ in SIDES}
    rng = np.random.default_rng(1234)
    q14s = rng.uniform(-np.pi, np.pi, size=(100, 14))
    expected = rig.kinematics.tcp_poses(q14s)  # (100, 2, 4, 4)
    pos_err, rot_err = 0.0, 0.0
    for n, q14 in enumerate(q14s):
        for side, arm, _ in SIDES:
            data.qpos[qadr[side]] = q14[arm]
        mujoco.mj_kinematics(model, data)
        for side, _, k in SIDES:
            T = expected[n, k]
            pos_err = max(pos_err, float(np.max(np.abs(data.site_xpos[site[side]] - T[:3, 3]))))
            R = data.site_xmat[site[side]].reshape(3, 3)
            rot_err = max(rot_err, float(np.max(np.abs(R - T[:3, :3]))))
    print(f"TCP agreement over 100 random joint vectors: max position error {pos_err:.3g} m, rotation {rot_err:.3g}")
    assert pos_err <= 1e-6
    assert rot_err <= 1e-6


# ---------------------------------------------------------------------- head camera projection


def _magenta(image: np.ndarray) -> np.ndarray:
    im = image.astype(np.int32)
    return (im[..., 0] > 100) & (im[..., 2] > 100) & (im[..., 1] < 80)


def test_cam_high_renders_points_where_the_camera_model_projects_them(rig: RigConfig) -> None:
    rng = np.random.default_rng(7)
    n, radius = 30, 0.01
    points = np.column_stack([rng.uniform(-0.2, 0.3, n), rng.uniform(-0.3, 0.3, n), rng.uniform(0.0, 0.3, n)])
    markers = [(f"marker_{i}", (float(p[0]), float(p[1]), float(p[2])), radius) for i, p in enumerate(points)]
    model = mujoco.MjModel.from_xml_string(build_mjcf(rig, markers=markers))
    data = mujoco.MjData(model)
    for side in ("left", "right"):  # swing both arms back, out of the head camera's view
        data.qpos[model.joint(f"{side}_joint_2").qposadr[0]] = -3.0
    mujoco.mj_forward(model, data)
    w, h = rig.image_size.width, rig.image_size.height
    renderer = make_renderer(model, w, h)
    camera = rig.head_camera_model
    assert (camera.width, camera.height) == (w, h) == (128, 128)
    uv, in_view = camera.project(points)
    ids = np.array([model.site(name).id for name, _, _ in markers])
    alpha = model.site_rgba[ids, 3].copy()
    errors: list[float] = []
    try:
        for i in range(n):
            # One marker at a time: neighbours that overlap in the image cannot bias a centroid.
            model.site_rgba[ids, 3] = 0.0
            model.site_rgba[ids[i], 3] = alpha[i]
            renderer.update_scene(data, camera="cam_high")
            mask = _magenta(renderer.render())
            if mask.sum() < 3 or not in_view[i]:
                continue
            margin = 3.0  # a marker cut by the image border has a biased centroid
            if not (margin <= uv[i, 0] <= w - 1 - margin and margin <= uv[i, 1] <= h - 1 - margin):
                continue
            v, u = np.nonzero(mask)
            errors.append(float(np.hypot(u.mean() - uv[i, 0], v.mean() - uv[i, 1])))
    finally:
        renderer.close()
    print(f"cam_high projection: {len(errors)} markers checked, max centroid error {max(errors):.3f} px")
    assert len(errors) >= 10
    assert max(errors) <= 1.5


# ---------------------------------------------------------------------- head cameras MuJoCo cannot render


def _rig_with_camera_file(tmp_path: Path, camera_file: Path) -> RigConfig:
    raw: dict[str, Any] = yaml.safe_load(SIM.read_text(encoding="utf-8"))
    raw["head_camera"] = {"file": str(camera_file)}
    path = tmp_path / "rig.yaml"
    path.write_text(yaml.safe_dump(raw), encoding="utf-8")
    return RigConfig.load(path)


def test_distorted_head_camera_is_refused_with_the_fix(tmp_path: Path) -> None:
    rig = _rig_with_camera_file(tmp_path, EXAMPLE_CAMERA)
    assert rig.head_camera_model.dist.any()
    with pytest.raises(ValueError, match=r"distortion-free head camera \(use head_camera\.look_at\)") as info:
        build_mjcf(rig)
    assert rig.name in str(info.value)


@pytest.mark.parametrize(
    ("change", "what"),
    [
        ({"cx": 4.0}, "cx"),
        ({"cy": -3.0}, "cy"),
        ({"fy": 1.05}, "fy"),
    ],
)
def test_off_centre_or_non_square_head_camera_is_refused(tmp_path: Path, change: dict[str, float], what: str) -> None:
    base = RigConfig.load(SIM).head_camera_model
    K = base.K.copy()
    if "cx" in change:
        K[0, 2] += change["cx"]
    if "cy" in change:
        K[1, 2] += change["cy"]
    if "fy" in change:
        K[1, 1] *= change["fy"]
    cam = dataclasses.replace(base, K=K)
    cam_file = tmp_path / "cam.yaml"
    cam.to_yaml(cam_file)
    assert CameraModel.from_yaml(cam_file) == cam
    rig = _rig_with_camera_file(tmp_path, cam_file)
    with pytest.raises(ValueError, match="square pixels and a centred principal point") as info:
        build_mjcf(rig)
    assert f"{what}=" in str(info.value) and rig.name in str(info.value)


def test_calibrated_camera_file_without_distortion_is_accepted(tmp_path: Path) -> None:
    base = RigConfig.load(SIM).head_camera_model
    cam_file = tmp_path / "cam.yaml"
    base.to_yaml(cam_file)
    rig = _rig_with_camera_file(tmp_path, cam_file)
    model: Any = compile_scene(build_mjcf(rig))
    assert model.camera("cam_high").id >= 0


# ---------------------------------------------------------------------- objects


@pytest.mark.parametrize(
    ("kwargs", "message"),
    [
        ({"bottom_radius": 0.05, "top_radius": 0.04}, r"need 0 < bottom_radius <= top_radius, got 0\.05, 0\.04"),
        ({"bottom_radius": 0.0, "top_radius": 0.04}, "need 0 < bottom_radius <= top_radius"),
        ({"bottom_radius": -0.01, "top_radius": 0.04}, "need 0 < bottom_radius <= top_radius"),
        ({"lip": 0.05}, r"need 0 <= lip < height, got lip=0\.05, height=0\.04"),
        ({"lip": 0.04}, "need 0 <= lip < height"),
        ({"lip": -0.001}, "need 0 <= lip < height"),
    ],
)
def test_bowl_object_rejects_impossible_dimensions(kwargs: dict[str, float], message: str) -> None:
    args: dict[str, Any] = {"bottom_radius": 0.03, "top_radius": 0.05, "height": 0.04, "rgba": (1, 0, 0, 1)}
    args["mass"] = 0.1
    args.update(kwargs)
    with pytest.raises(ValueError, match=message) as info:
        bowl_object("bowl_x", **args)
    assert str(info.value).startswith("bowl_x:")


def test_bowl_object_geometry() -> None:
    bowl = bowl_object("b", bottom_radius=0.03, top_radius=0.05, height=0.04, rgba=(1, 0, 0, 1), mass=0.1, segments=8)
    assert len(bowl.geoms) == 1 + 2 * 8  # base disc, wall plates, lip plates
    assert bowl.bottom == 0.0 and bowl.top == pytest.approx(0.04 + 0.006)
    no_lip = bowl_object("b", bottom_radius=0.03, top_radius=0.05, height=0.04, rgba=(1, 0, 0, 1), mass=0.1, lip=0.0)
    assert len(no_lip.geoms) == 1 + 12
    box = box_object("c", (0.01, 0.01, 0.02), (0, 1, 0, 1), 0.05)
    assert (box.bottom, box.top, box.extra["size"]) == (0.02, 0.02, 0.02)


def test_unsupported_geom_type_is_named() -> None:
    obj = ObjectSpec("thing", (GeomSpec("ellipsoid", (0.01, 0.02, 0.03), (1, 1, 1, 1)),), mass=0.1)
    with pytest.raises(ValueError, match=r"unsupported geom type 'ellipsoid' \(box, cylinder, sphere, capsule"):
        build_mjcf(RigConfig.load(SIM), [obj])


@pytest.mark.parametrize("name", packaged_tasks())
def test_every_task_scene_compiles(rig: RigConfig, name: str) -> None:
    task = load_task(name)
    objects = task.objects()
    assets = dict(scene_assets(objects, task.fixtures()).files)
    model: Any = compile_scene(build_mjcf(rig, objects, task.fixtures()), assets=assets)
    for obj in objects:
        body = model.body(obj.name)
        assert model.body_mass[body.id] == pytest.approx(obj.mass, rel=1e-4)
        assert model.jnt_type[model.joint(f"{obj.name}_free").id] == mujoco.mjtJoint.mjJNT_FREE
    for fx in task.fixtures():
        assert model.body(fx.name).id > 0
    for cam in rig.cameras:
        assert model.camera(cam).id >= 0
    assert model.nu == 2 * (6 + 2)  # arm joint servos and two finger servos per arm
    assert model.opt.timestep == pytest.approx(1.0 / (30 * 17))


def test_compile_scene_names_the_scene_on_error() -> None:
    with pytest.raises(ValueError, match="simulated rig scene does not compile"):
        compile_scene("<mujoco><worldbody><geom type='nope'/></worldbody></mujoco>")
