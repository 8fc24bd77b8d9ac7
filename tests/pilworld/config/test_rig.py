"""Rig configs: the shipped files load, and every kind of mistake names the file and the field."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import yaml

from pilworld.config import ConfigError, RigConfig
from pilworld.config.rig import letterbox
from pilworld.control_video.examples import HOME_Q14

ROOT = Path(__file__).resolve().parents[3]
SIM = ROOT / "configs" / "rig" / "sim_dual_ur5e.yaml"
REAL = ROOT / "configs" / "rig" / "real_dual_ur5e.yaml"


def test_sim_rig_loads() -> None:
    rig = RigConfig.load(SIM)
    assert rig.cameras == ("cam_high", "cam_left_wrist", "cam_right_wrist")
    spec = rig.robot_spec()
    assert spec.dof == 14 and spec.control_rate_hz == 30.0 and spec.image_size == (128, 128)
    assert spec.lower[6] == 0.0 and spec.upper[6] == 1.0
    cam = rig.head_camera_model
    assert (cam.width, cam.height) == (128, 128)
    # The home pose puts both grippers 10 cm above the table, left at +y, right at −y, both in view.
    pts = rig.kinematics.gripper_points(HOME_Q14)
    np.testing.assert_allclose(pts[:, 2], 0.10, atol=0.01)
    assert pts[0, 1] > 0.2 and pts[1, 1] < -0.2
    _, visible = cam.project(pts)
    assert visible.all()


def test_real_template_loads_and_letterboxes_the_calibrated_camera() -> None:
    rig = RigConfig.load(REAL)
    cam = rig.head_camera_model
    assert (cam.width, cam.height) == (224, 224)
    raw = RigConfig.load(REAL).head_camera
    assert raw.file is not None and Path(raw.file).is_absolute()


def test_letterbox_matches_resize_with_pad_geometry() -> None:
    from calib.camera_model import CameraModel

    cam = CameraModel.look_at(
        eye=np.array([0.0, -1.0, 1.0]),
        target=np.zeros(3),
        up=np.array([0.0, 0.0, 1.0]),
        fovy_deg=50.0,
        width=640,
        height=480,
    )
    pts = np.random.default_rng(0).uniform(-0.2, 0.2, size=(50, 3))
    uv, _ = cam.project(pts)
    boxed = letterbox(cam, 224, 224)
    uv2, _ = boxed.project(pts)
    # openpi: ratio = max(640/224, 480/224); resized to (224, 168); 28 rows of padding on top.
    s = 224 / 640
    expected = (uv + 0.5) * s - 0.5 + np.array([0.0, (224 - int(480 / (640 / 224))) // 2])
    np.testing.assert_allclose(uv2, expected, atol=1e-9)


def _write(tmp_path: Path, data: dict[str, object]) -> Path:
    path = tmp_path / "rig.yaml"
    path.write_text(yaml.safe_dump(data))
    return path


def _sim_data() -> dict[str, object]:
    data = yaml.safe_load(SIM.read_text())
    assert isinstance(data, dict)
    return data


@pytest.mark.parametrize(
    ("edit", "message"),
    [
        (lambda d: d["arms"]["left"].update(model="ur5x"), r"field 'arms\.left\.model'.*ur5e"),
        (lambda d: d["arms"].pop("right"), r"field 'arms\.right': Field required"),
        (lambda d: d.update(control_rate_hz=-1), r"field 'control_rate_hz'"),
        (lambda d: d.update(image_sise={"width": 1, "height": 1}), r"field 'image_sise': Extra inputs"),
        (
            lambda d: d["head_camera"].update(file="x.yaml"),
            r"field 'head_camera.file': camera file not found",
        ),
        (lambda d: d["arms"]["left"]["base_pose"].update(xyz=[0, 0]), r"field 'arms\.left\.base_pose\.xyz"),
        (lambda d: d["wrist_cameras"].update(cam_high=d["wrist_cameras"]["cam_left_wrist"]), "head camera"),
    ],
)
def test_rig_errors_name_file_and_field(tmp_path: Path, edit, message: str) -> None:  # type: ignore[no-untyped-def]
    data = _sim_data()
    edit(data)
    path = _write(tmp_path, data)
    with pytest.raises(ConfigError, match=message) as info:
        RigConfig.load(path)
    assert str(path) in str(info.value)


def test_both_camera_sources_is_an_error(tmp_path: Path) -> None:
    data = _sim_data()
    cam = tmp_path / "cam.yaml"
    RigConfig.load(SIM).head_camera_model.to_yaml(cam)
    data["head_camera"] = {"file": str(cam), "look_at": data["head_camera"]["look_at"]}  # type: ignore[index]
    with pytest.raises(ConfigError, match="exactly one of 'file'"):
        RigConfig.load(_write(tmp_path, data))


def test_camera_file_relative_to_rig_file(tmp_path: Path) -> None:
    data = _sim_data()
    (tmp_path / "calib").mkdir()
    original = RigConfig.load(SIM).head_camera_model
    original.to_yaml(tmp_path / "calib" / "head.yaml")
    data["head_camera"] = {"file": "calib/head.yaml"}
    rig = RigConfig.load(_write(tmp_path, data))
    np.testing.assert_array_equal(rig.head_camera_model.K, original.K)


def test_unreadable_files(tmp_path: Path) -> None:
    with pytest.raises(ConfigError, match="config file not found"):
        RigConfig.load(tmp_path / "missing.yaml")
    bad = tmp_path / "bad.yaml"
    bad.write_text("arms: [1, 2\n")
    with pytest.raises(ConfigError, match="not valid YAML"):
        RigConfig.load(bad)
    bad.write_text("- 1\n- 2\n")
    with pytest.raises(ConfigError, match="expected a mapping at the top level"):
        RigConfig.load(bad)
