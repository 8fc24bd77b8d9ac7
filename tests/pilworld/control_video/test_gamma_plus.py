"""Γ⁺ on the simulated rig: every style renders a chunk from a real start observation; each part is what
it claims to be (the paper's Γ byte for byte, the render black off the robot, the prior untouched off it);
bad input is refused in one line that names it."""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path
from typing import Any

import cv2
import numpy as np
import pytest

from pilworld.config.rig import RigConfig
from pilworld.control_video.cameras import RigCameras
from pilworld.control_video.examples import HOME_Q14, reach_and_grasp_chunk
from pilworld.control_video.gamma import ControlVideo
from pilworld.control_video.gamma_plus import ControlFrames, GammaPlus
from pilworld.control_video.lag import lagged_poses
from pilworld.control_video.reprojection import ROBOT_MARGIN
from pilworld.control_video.robot_render import make_robot_renderer
from pilworld.control_video.styles import STYLES, Style
from pilworld.types import HEAD_VIEW, ChunkSpec, Observation

SIM_RIG = Path(__file__).resolve().parents[3] / "configs" / "rig" / "sim_dual_ur5e.yaml"
SPEC = ChunkSpec()  # K = 15, Δ = 3, H = 50


@pytest.fixture(scope="module")
def rig() -> RigConfig:
    return RigConfig.load(SIM_RIG)


@pytest.fixture(scope="module")
def start(robots: Callable[[str], Any]) -> Observation:
    sim = robots("sort_cubes")
    sim.reset(seed=1_000_000, subtask=0, history=0)
    obs: Observation = sim.observe()
    return obs


@pytest.fixture(scope="module")
def chunk(start: Observation) -> np.ndarray[Any, Any]:
    """The example reach-and-grasp motion, started at the observed state."""
    c = reach_and_grasp_chunk(SPEC.horizon).astype(np.float64) - HOME_Q14 + start.state
    c[:, [6, 13]] = np.clip(c[:, [6, 13]], 0.0, 1.0)
    return c


@pytest.fixture(scope="module")
def frames(rig: RigConfig, start: Observation, chunk: np.ndarray[Any, Any]) -> dict[str, ControlFrames]:
    out = {}
    for style in STYLES:
        g = GammaPlus(rig, style, spec=SPEC)
        out[style] = g(chunk, previous_state=start.state, current_images=start.images, current_state=start.state)
    return out


@pytest.fixture(scope="module")
def future_parts(rig: RigConfig, chunk: np.ndarray[Any, Any], start: Observation) -> dict[str, np.ndarray[Any, Any]]:
    # Γ⁺ renders the arm where it will be: the commands delayed by the rig's servo lag (1 step on the sim rig).
    assert rig.control_lag_steps == 1
    poses = lagged_poses(chunk, start.state, SPEC, rig.control_lag_steps)
    np.testing.assert_array_equal(poses, chunk[SPEC.stride_indices() - 1])
    parts: dict[str, np.ndarray[Any, Any]] = make_robot_renderer(rig).render(poses).parts
    return parts


def test_zero_lag_renders_the_stride_aligned_actions(
    rig: RigConfig, chunk: np.ndarray[Any, Any], start: Observation
) -> None:
    g = GammaPlus(rig, "render", spec=SPEC, lag_steps=0)
    f = g(chunk, previous_state=start.state)
    want = make_robot_renderer(rig).render(chunk[SPEC.stride_indices()]).parts
    assert f.render is not None
    for view in f.views:
        np.testing.assert_array_equal(f.render.parts[view], want[view])
    with pytest.raises(ValueError, match="lag_steps"):
        GammaPlus(rig, "render", spec=SPEC, lag_steps=-1)


@pytest.mark.parametrize("style", STYLES)
def test_every_style_renders_a_chunk_in_every_view(
    rig: RigConfig, frames: dict[str, ControlFrames], style: str
) -> None:
    f = frames[style]
    s = Style.parse(style)
    assert f.style == style
    assert f.views == rig.cameras
    for view in f.views:
        img = f.images[view]
        assert img.dtype == np.uint8 and img.shape == (SPEC.frames, rig.image_size.height, rig.image_size.width, 3)
    assert (f.render is not None) == s.render
    assert (f.markers is not None) == s.markers
    assert (f.prior is not None) == s.prior
    head_drawn = f.images[HEAD_VIEW].any(axis=-1).mean(axis=(1, 2))
    assert np.all(head_drawn > 0.002), head_drawn  # something in every head frame
    if s.render or s.prior:  # wrist views show their own gripper or the scene
        for view in f.views[1:]:
            assert np.all(f.images[view].any(axis=-1).mean(axis=(1, 2)) > 0.05), view


def test_markers_style_is_the_papers_gamma_byte_for_byte(
    rig: RigConfig, frames: dict[str, ControlFrames], start: Observation, chunk: np.ndarray[Any, Any]
) -> None:
    gamma = ControlVideo.from_rig(rig)(chunk, start.state)
    f = frames["markers"]
    assert f.markers is not None
    assert f.images[HEAD_VIEW].tobytes() == gamma.tobytes()
    assert f.markers.tobytes() == gamma.tobytes()
    assert gamma.any()
    for view in f.views[1:]:
        assert not f.images[view].any(), view  # the paper's wrist views carry nothing
    # Drawn over the render, the markers are still Γ wherever they are drawn.
    both = frames["render+markers"].images[HEAD_VIEW]
    drawn = gamma.any(axis=-1)
    np.testing.assert_array_equal(both[drawn], gamma[drawn])


def test_render_style_is_black_exactly_off_the_robot(
    frames: dict[str, ControlFrames], future_parts: dict[str, np.ndarray[Any, Any]]
) -> None:
    f = frames["render"]
    assert f.render is not None and f.render.shaded is not None and f.render.depth is not None
    for view in f.views:
        mask = f.render.mask[view]
        np.testing.assert_array_equal(f.render.parts[view], future_parts[view])
        np.testing.assert_array_equal(f.images[view].any(axis=-1), mask)
        np.testing.assert_array_equal(f.images[view], f.render.shaded[view])
        assert np.all(f.render.depth[view][mask] > 0) and np.all(f.render.depth[view][~mask] == 0)
        assert mask.any(axis=(1, 2)).all(), view  # the robot is in every frame of every view


@pytest.mark.parametrize("style", ["prior", "render+prior", "markers+prior", "render+markers+prior"])
def test_prior_styles_show_the_prior_where_nothing_else_is_drawn(
    frames: dict[str, ControlFrames], future_parts: dict[str, np.ndarray[Any, Any]], style: str
) -> None:
    f = frames[style]
    assert f.prior is not None
    s = Style.parse(style)
    for view in f.views:
        robot = future_parts[view] > 0
        assert not f.prior.valid[view][robot].any(), view  # the future robot's pixels carry no scene
        assert not f.prior.images[view][robot].any(), view
        assert f.prior.valid[view].mean() > 0.3, view
        unmarked: np.ndarray[Any, Any] = np.ones_like(robot)
        if s.markers and view == HEAD_VIEW:
            assert f.markers is not None
            unmarked = np.asarray(~f.markers.any(axis=-1))
        free = unmarked & ~robot if s.render else unmarked
        np.testing.assert_array_equal(f.images[view][free], f.prior.images[view][free])
        if s.render:  # the shaded robot over the prior, the markers over both
            assert f.render is not None and f.render.shaded is not None
            shown = robot & unmarked
            np.testing.assert_array_equal(f.images[view][shown], f.render.shaded[view][shown])


def test_prior_of_the_head_is_the_current_frame_off_the_robot(
    rig: RigConfig, frames: dict[str, ControlFrames], start: Observation, future_parts: dict[str, np.ndarray[Any, Any]]
) -> None:
    prior = frames["prior"].prior
    assert prior is not None
    now = make_robot_renderer(rig).render(start.state).parts[HEAD_VIEW][0] > 0
    px = round(ROBOT_MARGIN * rig.image_size.width)
    kernel = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (2 * px + 1, 2 * px + 1))
    for k in range(SPEC.frames):
        future = future_parts[HEAD_VIEW][k] > 0
        near_future = cv2.dilate(future.astype(np.uint8), kernel) > 0  # the prior leaves the robot's margin too
        off = ~now & ~near_future
        np.testing.assert_array_equal(prior.images[HEAD_VIEW][k][off], start.images[HEAD_VIEW][off])
        assert prior.valid[HEAD_VIEW][k][off].all()
        assert not prior.valid[HEAD_VIEW][k][now | near_future].any()


def _one_line(exc: pytest.ExceptionInfo[BaseException]) -> str:
    msg = str(exc.value)
    assert "\n" not in msg, msg
    return msg


def test_unknown_style_is_refused(rig: RigConfig) -> None:
    with pytest.raises(ValueError, match=r"^style: .*'rendr'") as info:
        GammaPlus(rig, "rendr")
    assert "render+markers" in _one_line(info)  # lists what is allowed


@pytest.mark.parametrize(
    ("shape", "what"),
    [((50, 13), r"\(H, 14\).*\(50, 13\)"), ((30, 14), r"30 steps.*45"), ((2, 50, 14), r"one chunk")],
)
def test_bad_chunk_shapes_are_refused(rig: RigConfig, start: Observation, shape: tuple[int, ...], what: str) -> None:
    g = GammaPlus(rig, "render+markers")
    bad = np.broadcast_to(start.state[: shape[-1]], shape).copy()
    with pytest.raises(ValueError, match=rf"^(actions|chunk): .*{what}") as info:
        g(bad, previous_state=start.state)
    _one_line(info)


def test_nan_joints_are_refused(rig: RigConfig, start: Observation, chunk: np.ndarray[Any, Any]) -> None:
    bad = chunk.copy()
    bad[10, 3] = np.nan
    for style in ("render", "markers", "render+markers+prior"):
        with pytest.raises(ValueError, match=r"^(actions|chunk): .*non-finite") as info:
            GammaPlus(rig, style)(bad, previous_state=start.state, current_images=start.images)
        _one_line(info)
    state = start.state.astype(np.float64).copy()
    state[0] = np.inf
    with pytest.raises(ValueError, match=r"^current_state: ") as info:
        GammaPlus(rig, "prior")(chunk, current_images=start.images, current_state=state)
    _one_line(info)


def test_prior_without_current_images_is_refused(
    rig: RigConfig, start: Observation, chunk: np.ndarray[Any, Any]
) -> None:
    for kwargs in ({"current_state": start.state}, {"current_images": start.images}):
        with pytest.raises(ValueError, match=r"^style 'render\+prior': the prior needs current_images") as info:
            GammaPlus(rig, "render+prior")(chunk, **kwargs)
        _one_line(info)
    missing = {k: v for k, v in start.images.items() if k != "cam_right_wrist"}
    with pytest.raises(ValueError, match=r"^current_images: missing view\(s\) \['cam_right_wrist'\]") as info:
        GammaPlus(rig, "prior")(chunk, current_images=missing, current_state=start.state)
    _one_line(info)


def test_a_view_without_a_camera_model_is_refused(rig: RigConfig) -> None:
    with pytest.raises(ValueError, match=r"^views: .*'cam_nope'") as info:
        RigCameras.from_rig(rig, views=("cam_high", "cam_nope"))
    assert "cam_left_wrist" in _one_line(info)  # lists the cameras there are
    wrists = RigCameras.from_rig(rig, views=("cam_left_wrist", "cam_right_wrist"))
    with pytest.raises(ValueError, match=r"^style 'markers': markers are drawn in 'cam_high'"):
        GammaPlus(rig, "markers", cameras=wrists)
    only = GammaPlus(rig, "render", cameras=wrists)  # a render needs no head camera
    assert only.views == ("cam_left_wrist", "cam_right_wrist")


def test_a_missing_wrist_camera_file_is_named(rig: RigConfig, tmp_path: Path) -> None:
    data = rig.model_dump()
    data["wrist_cameras"]["cam_left_wrist"]["file"] = "left_wrist.yaml"
    with pytest.raises(ValueError, match=r"camera file not found: .*left_wrist\.yaml"):
        RigConfig.model_validate(data, context={"base_dir": tmp_path})
    # A file there when the rig was validated but gone when Γ⁺ is built: named too.
    rig.wrist_camera_model("cam_left_wrist").to_yaml(tmp_path / "left_wrist.yaml")
    with_file = RigConfig.model_validate(data, context={"base_dir": tmp_path})
    GammaPlus(with_file, "render")  # loads
    (tmp_path / "left_wrist.yaml").unlink()
    with pytest.raises((ValueError, FileNotFoundError), match=r"left_wrist\.yaml"):
        GammaPlus(with_file, "render")
