"""Γ⁺ on rigs other than the simulated one: the real-rig template (a distorted head camera, 224×224) and a
user's own MJCF robot named in the rig config."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
import pytest

from pilworld.config.rig import RigConfig
from pilworld.control_video.examples import HOME_Q14, reach_and_grasp_chunk
from pilworld.control_video.gamma import ControlVideo
from pilworld.control_video.gamma_plus import GammaPlus
from pilworld.control_video.robot_model import PART_IDS, RobotModel
from pilworld.control_video.robot_render import make_robot_renderer
from pilworld.control_video.robot_render_mujoco import MujocoRobotRenderer
from pilworld.types import HEAD_VIEW

RIGS = Path(__file__).resolve().parents[3] / "configs" / "rig"
Arr = np.ndarray[Any, Any]


@pytest.fixture(scope="module")
def real_rig() -> RigConfig:
    return RigConfig.load(RIGS / "real_dual_ur5e.yaml")


def _chunk_from(q0: Arr) -> Arr:
    """The example reach-and-grasp motion started at ``q0``."""
    c = reach_and_grasp_chunk().astype(np.float64) - HOME_Q14 + q0
    c[:, [6, 13]] = np.clip(c[:, [6, 13]], 0.0, 1.0)
    return c


@pytest.mark.parametrize("start", ["start_pose", "home"])
@pytest.mark.parametrize("style", ["render", "render+markers"])
def test_real_rig_renders_every_view_at_its_size(real_rig: RigConfig, style: str, start: str) -> None:
    assert real_rig.hardware is not None
    q0 = np.asarray(real_rig.hardware.start_pose if start == "start_pose" else HOME_Q14, dtype=np.float64)
    chunk = _chunk_from(q0)
    g = GammaPlus(real_rig, style)
    head = g.cameras.view(HEAD_VIEW).model
    assert head.dist.size and np.any(head.dist != 0)  # the template's calibrated (distorted) camera
    f = g(chunk, previous_state=q0)
    assert f.views == ("cam_high", "cam_left_wrist", "cam_right_wrist")
    assert f.render is not None
    for view in f.views:
        assert f.images[view].shape == (15, 224, 224, 3), view
        covered = f.render.mask[view].mean(axis=(1, 2))
        assert np.all(covered > 0.01), (view, covered)  # the robot in every frame of every view
        assert np.all(covered < 0.9), (view, covered)
    parts = set(np.unique(f.render.parts[HEAD_VIEW]).tolist())
    assert {PART_IDS["left_arm"], PART_IDS["right_arm"]} <= parts
    if "markers" in style:
        gamma = ControlVideo.from_rig(real_rig)(chunk, q0)
        assert f.markers is not None
        np.testing.assert_array_equal(f.markers, gamma)
        assert np.any(gamma, axis=(1, 2, 3)).all()  # the markers are in view throughout
        drawn = gamma.any(axis=-1)
        np.testing.assert_array_equal(f.images[HEAD_VIEW][drawn], gamma[drawn])


def _arm(side: str, y: float) -> str:
    """Six hinge joints along a chain of capsules, then a hand with two sliding box fingers."""
    p = side[0].upper()
    axes = ["0 0 1", "0 1 0", "0 1 0", "0 1 0", "1 0 0", "0 0 1"]
    links = [("0 0 0", "0 0 0.12"), ("0 0 0.12", "0.12 0 0")] + [("0.12 0 0", "0.10 0 0")] * 4
    xml = f'<body name="{p}_base" pos="0 {y} 0"><geom type="cylinder" size="0.05 0.02"/>'
    for i, ((pos, to), axis) in enumerate(zip(links, axes, strict=True)):
        xml += (
            f'<body name="{p}_link{i + 1}" pos="{pos}"><joint name="{p}{i + 1}" type="hinge" axis="{axis}"/>'
            f'<geom type="capsule" fromto="0 0 0 {to}" size="0.03"/>'
        )
    xml += f'<body name="{p}_hand" pos="0.1 0 0"><geom type="box" size="0.02 0.05 0.02"/>'
    for finger, sign in (("a", 1), ("b", -1)):
        xml += (
            f'<body name="{p}_finger_{finger}" pos="0 {sign * 0.02} -0.04">'
            f'<joint name="{p}f_{finger}" type="slide" axis="0 {sign} 0" range="0 0.03"/>'
            '<geom type="box" size="0.012 0.008 0.03"/></body>'
        )
    return xml + "</body>" + "</body>" * 6 + "</body>"


def _user_rig(tmp_path: Path, arm_joints: dict[str, list[str]] | None = None) -> RigConfig:
    (tmp_path / "robot.xml").write_text(
        f'<mujoco model="toy_dual_arm"><worldbody>{_arm("left", 0.22)}{_arm("right", -0.22)}</worldbody></mujoco>'
    )
    data = RigConfig.load(RIGS / "sim_dual_ur5e.yaml").model_dump()
    data["robot_model"] = {
        "mjcf": "robot.xml",
        "arm_joints": arm_joints or {s: [f"{s[0].upper()}{i}" for i in range(1, 7)] for s in ("left", "right")},
        "finger_joints": {s: [f"{s[0].upper()}f_a", f"{s[0].upper()}f_b"] for s in ("left", "right")},
    }
    return RigConfig.model_validate(data, context={"base_dir": tmp_path})


def test_a_user_mjcf_robot_renders_with_its_parts(tmp_path: Path) -> None:
    rig = _user_rig(tmp_path)
    robot = RobotModel.from_rig(rig)
    assert robot.source.endswith("robot.xml")
    assert sorted(set(robot.geom_part.tolist())) == [1, 2, 3, 4]
    q = np.zeros((2, 14))
    q[:, [6, 13]] = (1.0, 0.0)  # left open, right closed
    q[1, [1, 8]] = 0.4  # both shoulders lowered
    g = GammaPlus(rig, "render+markers")
    frames = g(np.broadcast_to(q[1], (50, 14)).copy(), previous_state=q[0])
    assert frames.render is not None
    assert set(np.unique(frames.render.parts[HEAD_VIEW]).tolist()) == {0, 1, 2, 3, 4}
    a = make_robot_renderer(rig, robot=robot).render(q)
    assert set(np.unique(a.parts[HEAD_VIEW][1]).tolist()) == {0, 1, 2, 3, 4}
    assert {0, 1, 3} <= set(np.unique(a.parts[HEAD_VIEW][0]).tolist())  # straight out: fingers under the hand
    # The grip drives the slide joints: 1 (open) the upper end of their range, 0 the lower.
    qpos = robot.qpos(q)
    left, right = robot.finger_qadr["left"], robot.finger_qadr["right"]
    np.testing.assert_allclose(qpos[0, left], 0.03)
    np.testing.assert_allclose(qpos[0, right], 0.0)
    # MuJoCo draws the same robot.
    with MujocoRobotRenderer(robot, g.cameras) as ref:
        m = ref.render(q, shaded=False)
    A, M = a.mask[HEAD_VIEW], m.mask[HEAD_VIEW]
    assert (A & M).sum() / (A | M).sum() > 0.95
    assert ((a.parts[HEAD_VIEW] == m.parts[HEAD_VIEW]) & (A | M)).sum() / (A | M).sum() > 0.95


def test_a_missing_joint_name_lists_the_models_joints(tmp_path: Path) -> None:
    joints = {"left": ["L1", "L2", "L3", "L4", "L5", "L_wrist_3"], "right": [f"R{i}" for i in range(1, 7)]}
    rig = _user_rig(tmp_path, joints)  # the config cannot know the model's joints; building the model does
    with pytest.raises(ValueError, match=r"^arm_joints\.left: joint 'L_wrist_3' not in the robot model") as info:
        GammaPlus(rig, "render")
    msg = str(info.value)
    assert "\n" not in msg
    for name in ("L1", "L6", "R6", "Lf_a", "Rf_b"):
        assert f"'{name}'" in msg, name


def test_a_missing_mjcf_file_is_named(tmp_path: Path) -> None:
    data = RigConfig.load(RIGS / "sim_dual_ur5e.yaml").model_dump()
    joints = {s: [f"j{i}" for i in range(6)] for s in ("left", "right")}
    data["robot_model"] = {"mjcf": "nope.xml", "arm_joints": joints}
    with pytest.raises(ValueError, match=r"robot model file not found: .*nope\.xml"):
        RigConfig.model_validate(data, context={"base_dir": tmp_path})
