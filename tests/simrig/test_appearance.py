"""The simulated rig's ``appearance``: ``flat`` unchanged, ``varied`` textured, lit per episode and
post-processed like a camera's images, all seeded; physics identical under both."""

from __future__ import annotations

import dataclasses
from collections.abc import Iterator
from pathlib import Path

import cv2
import numpy as np
import pytest

from pilworld.perception.colour import ColourClass, segment
from simrig import appearance as app
from simrig.objects import GeomSpec, ObjectSpec
from simrig.poses import HOME_Q14
from simrig.robot import SimRobot
from simrig.scene import build_mjcf

ROOT = Path(__file__).resolve().parents[2]
SIM = ROOT / "configs" / "rig" / "sim_dual_ur5e.yaml"


def _images(robot: SimRobot) -> dict[str, np.ndarray]:
    return dict(robot.observe().images)


def _moves(n: int = 8) -> list[np.ndarray]:
    """A few commands that move both arms and close one gripper (object contact not needed)."""
    out = []
    for k in range(n):
        a = HOME_Q14.astype(np.float64).copy()
        a[:6] += 0.02 * (k + 1) * np.array([1.0, -0.5, 0.5, 1.0, -1.0, 0.5])
        a[7:13] -= 0.015 * (k + 1)
        a[6] = 1.0 - 0.1 * k
        out.append(a)
    return out


@pytest.fixture(scope="module")
def varied() -> Iterator[SimRobot]:
    robot = SimRobot(SIM, "sort_cubes", appearance="varied")
    robot.connect()
    yield robot
    robot.disconnect()


def test_bad_appearance_is_a_clear_error() -> None:
    with pytest.raises(ValueError, match=r"^appearance: expected one of flat, varied, got 'x'$"):
        SimRobot(SIM, "sort_cubes", appearance="x")
    with pytest.raises(ValueError, match="appearance: expected one of flat, varied, got 'Varied'"):
        app.check_appearance("Varied")
    robot = SimRobot(SIM, "sort_cubes")
    with pytest.raises(ValueError, match="appearance: expected one of flat, varied, got None"):
        build_mjcf(robot.rig, appearance=None)  # type: ignore[arg-type]
    assert app.APPEARANCES == ("flat", "varied")


def test_flat_is_the_default_and_byte_identical() -> None:
    default = SimRobot(SIM, "sort_cubes")
    flat = SimRobot(SIM, "sort_cubes", appearance="flat")
    assert default.appearance == flat.appearance == "flat"
    assert flat.xml == default.xml
    assert "material" not in default.xml and 'castshadow="false"' in default.xml
    with default, flat:
        for robot in (default, flat):
            robot.reset(seed=3, subtask=1, history=2, stride=2)
            assert robot.look is None
        a, b = _images(default), _images(flat)
        assert a.keys() == b.keys()
        for cam in a:
            assert np.array_equal(a[cam], b[cam]), cam
        for action in _moves(3):
            default.send_action(action)
            flat.send_action(action)
        assert np.array_equal(default.state(), flat.state())
        for cam, image in _images(default).items():
            assert np.array_equal(image, flat.render(cam)), cam


def test_varied_differs_from_flat_and_keeps_the_contract(varied: SimRobot) -> None:
    assert varied.appearance == "varied"
    assert 'castshadow="true"' in varied.xml and app.table_material_name(0) in varied.xml
    with SimRobot(SIM, "sort_cubes") as flat:
        flat.reset(seed=4, history=0)
        start = varied.reset(seed=4, history=0)
        assert isinstance(varied.look, app.Look)
        f = _images(flat)
        for cam, image in start.observation.images.items():
            assert image.dtype == np.uint8 and image.shape == f[cam].shape == (128, 128, 3)
            assert image.flags["C_CONTIGUOUS"]
            diff = np.abs(image.astype(np.int16) - f[cam].astype(np.int16))
            assert diff.mean() > 5.0, f"{cam}: varied looks like flat (mean |diff| {diff.mean():.2f})"
        # Not flat: the table of the varied look is textured and noisy (a flat patch of it is not uniform).
        patch = start.observation.images["cam_high"][20:40, 50:80].astype(np.float64)
        assert patch.std(axis=(0, 1)).mean() > 2.0


def test_same_seed_same_images_other_seed_other_light(varied: SimRobot) -> None:
    with SimRobot(SIM, "sort_cubes", appearance="varied") as other:
        a = varied.reset(seed=7, subtask=1, history=2, stride=2)
        b = other.reset(seed=7, subtask=1, history=2, stride=2)
        assert varied.look == other.look == app.draw_look(7, 1)
        for fa, fb in zip((*a.history, a.observation), (*b.history, b.observation), strict=True):
            for cam in fa.images:
                assert np.array_equal(fa.images[cam], fb.images[cam]), cam
        for action in _moves(4):
            varied.send_action(action)
            other.send_action(action)
        for cam, image in _images(varied).items():
            assert np.array_equal(image, other.render(cam)), cam
        # The frame noise moves on with the frame: the same scene one step later is another frame.
        history = a.history
        assert not np.array_equal(history[0].images["cam_high"], history[1].images["cam_high"])

        other.reset(seed=8, subtask=1, history=0)
        varied.reset(seed=7, subtask=1, history=0)
        assert other.look is not None and varied.look is not None
        assert other.look.light_dir != varied.look.light_dir
        assert other.look.light_diffuse != varied.look.light_diffuse
        model_a, model_b = varied._model, other._model
        assert not np.array_equal(model_a.light_dir, model_b.light_dir)
        assert not np.array_equal(_images(varied)["cam_high"], _images(other)["cam_high"])


def test_physics_does_not_depend_on_appearance(varied: SimRobot) -> None:
    with SimRobot(SIM, "sort_cubes") as flat:
        starts = [r.reset(seed=5, subtask=0, history=2, stride=3) for r in (flat, varied)]
        assert np.array_equal(starts[0].observation.state, starts[1].observation.state)
        for action in _moves(8):
            sent = [r.send_action(action) for r in (flat, varied)]
            assert np.array_equal(sent[0], sent[1])
            assert np.array_equal(flat.state(), varied.state())
            varied.observe()  # rendering in between changes nothing
        assert np.array_equal(flat._data.qpos, varied._data.qpos)
        assert np.array_equal(flat._data.qvel, varied._data.qvel)
        assert flat.object_poses() == varied.object_poses()


def test_colour_finder_still_sees_every_object(varied: SimRobot) -> None:
    """Object textures keep their flat colour's hue and mean: a hue-based detector still finds them."""
    classes = [ColourClass(n, varied.task.colour(n)) for n in varied.task.object_names]
    for seed in range(4):
        varied.reset(seed=seed, history=0)
        masks = segment(varied.render("cam_high"), classes)
        for name, mask in masks.items():
            assert mask.sum() >= 8, f"seed {seed}: {name} not found ({mask.sum()} px)"
        # ...and no table pixel passes as an object: every class is one blob's worth of pixels at most.
        assert all(mask.sum() < 200 for mask in masks.values())


def test_look_draws_are_seeded_and_bounded() -> None:
    assert app.draw_look(3, 0) == app.draw_look(3, 0)
    assert app.draw_look(3, 0) != app.draw_look(3, 1) != app.draw_look(4, 1)
    looks = [app.draw_look(s, k) for s in range(40) for k in range(2)]
    assert {lk.table_material for lk in looks} == set(range(len(app.TABLE_MATERIALS)))
    for lk in looks:
        assert abs(np.linalg.norm(lk.light_dir) - 1.0) < 1e-9 and lk.light_dir[2] < -0.7
        assert 70 <= lk.jpeg_quality <= 90 and 0.85 <= lk.exposure <= 1.1
        assert max(lk.white_balance) / min(lk.white_balance) < 1.25
    with pytest.raises(ValueError, match="seed: expected an integer >= 0"):
        app.draw_look(-1, 0)
    with pytest.raises(ValueError, match="frame: expected an integer >= 0"):
        app.camera_effects(np.zeros((4, 4, 3), np.uint8), looks[0], frame=-1, camera="cam_high")
    with pytest.raises(ValueError, match=r"image: expected uint8 \(H, W, 3\)"):
        app.camera_effects(np.zeros((4, 4), np.uint8), looks[0], frame=0, camera="cam_high")


def test_camera_effects_are_deterministic_per_frame_and_camera() -> None:
    look = app.draw_look(11, 2)
    image = np.full((64, 48, 3), 120, np.uint8)
    image[:, 24:] = (200, 60, 30)
    a = app.camera_effects(image, look, frame=5, camera="cam_high")
    assert a.dtype == np.uint8 and a.shape == image.shape
    assert np.array_equal(a, app.camera_effects(image.copy(), look, frame=5, camera="cam_high"))
    assert not np.array_equal(a, app.camera_effects(image, look, frame=6, camera="cam_high"))
    assert not np.array_equal(a, app.camera_effects(image, look, frame=5, camera="cam_left_wrist"))
    assert np.array_equal(image[0, 0], (120, 120, 120))  # the input is not modified
    # Gains and noise, but the picture survives: the mean moves by the gains, the noise (what JPEG leaves
    # of it on a flat patch) is a DN or so, the edge between the halves stays put.
    gains = np.asarray(look.white_balance) * look.exposure
    left = a[8:-8, 4:18].reshape(-1, 3).astype(np.float64)
    assert np.allclose(left.mean(axis=0), 120 * gains, atol=3.0)
    assert 0.2 < left.std(axis=0).mean() < 8.0
    assert len(np.unique(left, axis=0)) > 5
    right = a[8:-8, 30:44].reshape(-1, 3).astype(np.float64).mean(axis=0)
    assert np.allclose(right, np.minimum(255, np.array([200, 60, 30]) * gains), atol=6.0)


def test_textures_keep_colours_and_stay_grey_on_the_table() -> None:
    for k in range(len(app.TABLE_MATERIALS)):
        hsv = cv2.cvtColor(app.table_image(k), cv2.COLOR_RGB2HSV)
        assert hsv[:, :, 1].max() < 0.3 * 255, f"table material {k} is too saturated for a colour finder"
        assert hsv[:, :, 2].std() > 3.0  # textured, not flat
    for rgb in [(0.95, 0.80, 0.10), (0.15, 0.70, 0.25), (0.50, 0.25, 0.75), (0.25, 0.25, 0.27)]:
        image = app.object_image(rgb)
        mean = image.reshape(-1, 3).mean(axis=0) / 255.0
        assert np.allclose(mean, rgb, atol=0.01), (rgb, mean)
        assert image.astype(np.float64).std(axis=(0, 1)).max() > 3.0
    # A geom with its own material keeps it; flat-coloured ones get a texture of their colour (shared).
    own = GeomSpec("box", (0.02, 0.02, 0.02), (1.0, 1.0, 1.0, 1.0), material="mat_mine")
    plain = GeomSpec("box", (0.02, 0.02, 0.02), (0.9, 0.2, 0.2, 1.0))
    obj = ObjectSpec("thing", (own, plain, dataclasses.replace(plain, pos=(0.0, 0.0, 0.04))), mass=0.1)
    (new,), (), assets = app.textured_scene([obj], [])
    assert new.geoms[0] == own
    assert new.geoms[1].material == new.geoms[2].material and new.geoms[1].material is not None
    assert new.geoms[1].rgba == (1.0, 1.0, 1.0, 1.0)
    names = [f for f, _ in assets.files]
    assert len(names) == len(set(names)) == 1 + len(app.TABLE_MATERIALS)


def test_sim_backend_passes_the_appearance_through() -> None:
    from hw_drivers.fakes.backend import SimBackend

    backend = SimBackend(SIM, "sort_cubes", appearance="varied", camera_fps=2.0)
    try:
        assert backend.call(lambda robot: robot.appearance) == "varied"
    finally:
        backend.close()
