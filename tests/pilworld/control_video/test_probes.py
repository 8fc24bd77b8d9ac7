"""Stability probes: perturbations of exactly the asked size, a zero probe that changes nothing, sensitivity
that grows with the error, and a mismatched robot that grows, shrinks and recolours as asked."""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from pilworld.config.rig import RigConfig
from pilworld.control_video.cameras import RigCameras
from pilworld.control_video.examples import HOME_Q14, random_chunks, reach_and_grasp_chunk
from pilworld.control_video.gamma_plus import GammaPlus
from pilworld.control_video.probes import (
    mismatched_robot,
    perturb_transform,
    perturbed_cameras,
    perturbed_gamma_plus,
    render_sensitivity,
)
from pilworld.control_video.robot_model import RobotModel
from pilworld.control_video.robot_render import make_robot_renderer
from pilworld.geometry import invert_transform, pose_to_matrix
from pilworld.types import HEAD_VIEW

SIM_RIG = Path(__file__).resolve().parents[3] / "configs" / "rig" / "sim_dual_ur5e.yaml"


@pytest.fixture(scope="module")
def rig() -> RigConfig:
    return RigConfig.load(SIM_RIG)


@pytest.fixture(scope="module")
def chunks() -> np.ndarray[Any, Any]:
    return random_chunks(2, seed=3)


def _angle_deg(R: np.ndarray[Any, Any]) -> float:
    return math.degrees(math.acos(float(np.clip((np.trace(R) - 1.0) / 2.0, -1.0, 1.0))))


@pytest.mark.parametrize(("t", "a"), [(0.005, 0.0), (0.0, 0.5), (0.02, 2.0), (0.001, 179.0)])
def test_perturb_transform_has_exactly_the_requested_size(t: float, a: float) -> None:
    T = pose_to_matrix([0.3, -0.2, 0.9], [0.4, -1.1, 2.0])
    for seed in range(5):
        P = perturb_transform(T, t, a, np.random.default_rng(seed))
        E = P @ invert_transform(T)
        assert np.linalg.norm(E[:3, 3]) == pytest.approx(t, abs=1e-12)
        assert _angle_deg(E[:3, :3]) == pytest.approx(a, abs=1e-6)
        # Read as a camera pose T_cam_x: its centre moves by exactly t.
        c0, c1 = invert_transform(T)[:3, 3], invert_transform(P)[:3, 3]
        assert np.linalg.norm(c1 - c0) == pytest.approx(t, abs=1e-12)
        np.testing.assert_allclose(P[:3, :3].T @ P[:3, :3], np.eye(3), atol=1e-12)


def test_perturb_transform_is_deterministic_per_rng_and_random_in_direction() -> None:
    T = np.eye(4)
    a = perturb_transform(T, 0.01, 1.0, np.random.default_rng(7))
    b = perturb_transform(T, 0.01, 1.0, np.random.default_rng(7))
    c = perturb_transform(T, 0.01, 1.0, np.random.default_rng(8))
    np.testing.assert_array_equal(a, b)
    assert not np.allclose(a, c)
    # The same seed gives the same direction at every size.
    d = perturb_transform(T, 0.03, 0.0, np.random.default_rng(7))
    e = perturb_transform(T, 0.01, 0.0, np.random.default_rng(7))
    np.testing.assert_allclose(d[:3, 3], 3 * e[:3, 3], atol=1e-15)
    np.testing.assert_array_equal(perturb_transform(T, 0.0, 0.0, np.random.default_rng(1)), T)


@pytest.mark.parametrize(
    ("kwargs", "name"),
    [
        ({"translation_m": -0.001}, "translation_m"),
        ({"translation_m": math.nan}, "translation_m"),
        ({"rotation_deg": math.inf}, "rotation_deg"),
        ({"rotation_deg": -1.0}, "rotation_deg"),
        ({"rotation_deg": 200.0}, "rotation_deg"),
        ({"T": np.full((4, 4), np.nan)}, "T"),
        ({"T": np.eye(3)}, "T"),
        ({"rng": 3}, "rng"),
    ],
)
def test_perturb_transform_refuses_bad_input(kwargs: dict[str, Any], name: str) -> None:
    args: dict[str, Any] = {"T": np.eye(4), "translation_m": 0.0, "rotation_deg": 0.0, "rng": np.random.default_rng()}
    args.update(kwargs)
    with pytest.raises(ValueError, match=rf"^{name}: ") as info:
        perturb_transform(**args)
    assert "\n" not in str(info.value)


def test_perturbed_cameras_move_head_on_the_rig_and_wrists_on_their_mounts(rig: RigConfig) -> None:
    nominal = RigCameras.from_rig(rig)
    cams = perturbed_cameras(
        rig, head_translation_m=0.004, head_rotation_deg=0.3, wrist_translation_m=0.006, wrist_rotation_deg=0.7, seed=2
    )
    assert cams.names == nominal.names
    wrist_errors = []
    for v0, v1 in zip(nominal.views, cams.views, strict=True):
        E = v1.model.T_cam_base @ invert_transform(v0.model.T_cam_base)
        t, a = (0.004, 0.3) if v0.arm is None else (0.006, 0.7)
        assert np.linalg.norm(E[:3, 3]) == pytest.approx(t, abs=1e-12), v0.name
        assert _angle_deg(E[:3, :3]) == pytest.approx(a, abs=1e-5), v0.name
        np.testing.assert_array_equal(v1.model.K, v0.model.K)
        assert v1.arm == v0.arm
        if v0.arm is not None:
            wrist_errors.append(E)
    assert not np.allclose(wrist_errors[0], wrist_errors[1])  # each wrist its own draw
    # Wrist errors ride on the TCP: the camera's offset from its TCP is off by the same 6 mm at any q.
    q = np.stack([HOME_Q14, reach_and_grasp_chunk()[-1]])
    p0, p1 = nominal.poses(q), cams.poses(q)
    for v in nominal.views:
        if v.arm is not None:
            c0 = invert_transform(p0[v.name])[:, :3, 3]
            c1 = invert_transform(p1[v.name])[:, :3, 3]
            np.testing.assert_allclose(np.linalg.norm(c1 - c0, axis=-1), 0.006, atol=1e-9)
    # Only the wrists moved: the head stays where it was.
    only_wrist = perturbed_cameras(rig, wrist_translation_m=0.01)
    np.testing.assert_array_equal(only_wrist.view(HEAD_VIEW).model.T_cam_base, nominal.view(HEAD_VIEW).model.T_cam_base)


@pytest.mark.parametrize(
    ("kwargs", "name"),
    [
        ({"head_translation_m": -0.01}, "head_translation_m"),
        ({"wrist_rotation_deg": math.nan}, "wrist_rotation_deg"),
        ({"seed": -1}, "seed"),
    ],
)
def test_perturbed_cameras_refuse_bad_input(rig: RigConfig, kwargs: dict[str, Any], name: str) -> None:
    with pytest.raises(ValueError, match=rf"^{name}: "):
        perturbed_cameras(rig, **kwargs)


def test_zero_perturbation_reproduces_the_nominal_gamma_plus_bit_for_bit(
    rig: RigConfig, chunks: np.ndarray[Any, Any]
) -> None:
    nominal = GammaPlus(rig, "render+markers")(chunks[0], previous_state=HOME_Q14)
    probe = perturbed_gamma_plus(rig, "render+markers")(chunks[0], previous_state=HOME_Q14)
    for view in nominal.views:
        np.testing.assert_array_equal(probe.images[view], nominal.images[view])
    assert nominal.render is not None and probe.render is not None and nominal.render.depth is not None
    for view in nominal.views:
        np.testing.assert_array_equal(probe.render.parts[view], nominal.render.parts[view])
        np.testing.assert_array_equal(probe.render.depth[view], nominal.render.depth[view])  # type: ignore[index]
    [summary] = render_sensitivity(rig, chunks, [{}])
    assert summary["iou"] == {v: 1.0 for v in nominal.views}
    assert summary["tcp_shift_px"] == 0.0


def test_head_error_moves_render_and_markers_together(rig: RigConfig, chunks: np.ndarray[Any, Any]) -> None:
    nominal = GammaPlus(rig, "render+markers")(chunks[0])
    probe = perturbed_gamma_plus(rig, "render+markers", head_translation_m=0.02, head_rotation_deg=1.0)(chunks[0])
    assert nominal.markers is not None and probe.markers is not None
    assert not np.array_equal(probe.markers, nominal.markers)
    assert nominal.render is not None and probe.render is not None
    assert not np.array_equal(probe.render.parts[HEAD_VIEW], nominal.render.parts[HEAD_VIEW])
    for view in nominal.views[1:]:  # wrists untouched by a head error
        np.testing.assert_array_equal(probe.images[view], nominal.images[view])


@pytest.mark.parametrize("which", ["head", "wrist"])
def test_sensitivity_grows_with_the_perturbation(rig: RigConfig, chunks: np.ndarray[Any, Any], which: str) -> None:
    sizes = (0.0, 0.005, 0.02)
    out = render_sensitivity(rig, chunks, [{f"{which}_translation_m": s, "seed": 4} for s in sizes])
    assert [o["perturbation"][f"{which}_translation_m"] for o in out] == list(sizes)
    assert all(o["frames"] == 2 * 15 for o in out)
    views = [v for v in out[0]["iou"] if (v == HEAD_VIEW) == (which == "head")]
    others = [v for v in out[0]["iou"] if v not in views]
    for v in views:
        ious = [o["iou"][v] for o in out]
        assert ious[0] == 1.0 > ious[1] > ious[2], (v, ious)
        assert ious[2] < 0.97, (v, ious)  # 2 cm is seen
    for v in others:
        assert all(o["iou"][v] == 1.0 for o in out), v
    shifts = [o["tcp_shift_px"] for o in out]
    if which == "head":
        assert shifts[0] == 0.0 < shifts[1] < shifts[2], shifts
        assert shifts[2] == pytest.approx(4 * shifts[1], rel=0.1)  # small errors: shift ∝ translation
        assert all(o["tcp_shift_px_max"] >= o["tcp_shift_px"] for o in out)
    else:
        assert shifts == [0.0, 0.0, 0.0]


def test_sensitivity_grows_with_rotation_and_is_json_able(rig: RigConfig, chunks: np.ndarray[Any, Any]) -> None:
    import json

    out = render_sensitivity(rig, chunks[:1], [{"head_rotation_deg": a} for a in (0.2, 0.5, 2.0)])
    json.dumps(out)  # plain floats, lists and None only
    ious = [o["iou"][HEAD_VIEW] for o in out]
    shifts = [o["tcp_shift_px"] for o in out]
    assert ious[0] > ious[1] > ious[2] and shifts[0] < shifts[1] < shifts[2]


@pytest.mark.parametrize("scale", [0.8, 1.2])
def test_radius_scale_grows_or_shrinks_the_mask(rig: RigConfig, scale: float) -> None:
    chunk = random_chunks(1, seed=5)
    q = chunk[0, 2::3]
    base = make_robot_renderer(rig).render(q, depth=False, shaded=False)
    robot = mismatched_robot(rig, radius_scale=scale)
    out = make_robot_renderer(rig, robot=robot).render(q, depth=False, shaded=False)
    area0 = base.mask[HEAD_VIEW].sum()
    area1 = out.mask[HEAD_VIEW].sum()
    if scale > 1:
        assert area1 > 1.08 * area0
        assert out.mask[HEAD_VIEW][base.mask[HEAD_VIEW]].mean() > 0.99  # fatter links cover the old
    else:
        assert area1 < 0.92 * area0
        assert base.mask[HEAD_VIEW][out.mask[HEAD_VIEW]].mean() > 0.99
    [summary] = render_sensitivity(rig, chunk, [{"radius_scale": scale}])
    assert (summary["area_ratio"][HEAD_VIEW] > 1.0) == (scale > 1.0)
    nominal = RobotModel.from_rig(rig)
    np.testing.assert_array_equal(robot.geom_part, nominal.geom_part)


def test_colours_change_shading_but_not_parts(rig: RigConfig) -> None:
    q = np.stack([HOME_Q14, reach_and_grasp_chunk()[-1]])
    base = make_robot_renderer(rig).render(q)
    red = make_robot_renderer(rig, robot=mismatched_robot(rig, rgba=(0.9, 0.1, 0.1, 1.0))).render(q)
    assert base.shaded is not None and red.shaded is not None
    for view in base.views:
        np.testing.assert_array_equal(red.parts[view], base.parts[view])
        assert not np.array_equal(red.shaded[view], base.shaded[view])
        robot = red.mask[view]
        r, g = red.shaded[view][robot][:, 0].astype(int), red.shaded[view][robot][:, 1].astype(int)
        assert np.all(r >= g), view  # every robot pixel is red now
        assert np.all(red.shaded[view][~robot] == 0)


@pytest.mark.parametrize(
    ("kwargs", "name"),
    [
        ({"radius_scale": 0.4}, "radius_scale"),
        ({"radius_scale": 2.5}, "radius_scale"),
        ({"radius_scale": math.nan}, "radius_scale"),
        ({"rgba": (1.0, 0.0, 0.0)}, "rgba"),
        ({"rgba": (1.0, 0.0, 2.0, 1.0)}, "rgba"),
        ({"rgba": "red"}, "rgba"),
    ],
)
def test_mismatched_robot_refuses_bad_input(rig: RigConfig, kwargs: dict[str, Any], name: str) -> None:
    with pytest.raises(ValueError, match=rf"^{name}: ") as info:
        mismatched_robot(rig, **kwargs)
    assert "\n" not in str(info.value)


def test_render_sensitivity_refuses_bad_input(rig: RigConfig, chunks: np.ndarray[Any, Any]) -> None:
    with pytest.raises(ValueError, match=r"^perturbation: unknown key\(s\) \['head_shift'\]"):
        render_sensitivity(rig, chunks, [{"head_shift": 0.01}])
    with pytest.raises(ValueError, match=r"^chunks: "):
        render_sensitivity(rig, chunks[..., :13], [{}])
    with pytest.raises(ValueError, match=r"^chunks: 30 steps"):
        render_sensitivity(rig, chunks[:, :30], [{}])
    bad = chunks.copy()
    bad[0, 5, 3] = np.nan
    with pytest.raises(ValueError, match=r"^chunks: contains non-finite"):
        render_sensitivity(rig, bad, [{}])
    with pytest.raises(ValueError, match=r"^wrist_translation_m: "):
        render_sensitivity(rig, chunks, [{"wrist_translation_m": -1.0}])
