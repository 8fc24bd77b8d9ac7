"""The geometric candidate layers of world model v2: hold spans, per-step chunks, the carried warp."""

from __future__ import annotations

import numpy as np
import pytest

from pilworld.config.rig import RigConfig
from pilworld.types import ARM_LAYOUT, ChunkSpec
from pilworld.world_model.composite.layers import HOLD_MAX, LayerBuilder, hold_spans, steps_from_stride
from simrig.poses import HOME_Q14

SPEC = ChunkSpec()
LEFT_ARM, LEFT_GRIP = ARM_LAYOUT["left"]


def test_hold_spans() -> None:
    assert hold_spans(np.array([1.0, 1.0, 1.0])) == (None, None)
    assert hold_spans(np.array([1.0, 0.9, 0.2, 0.0])) == (2, None)
    assert hold_spans(np.array([0.3, 0.3, 1.0, 1.0])) == (0, 2)
    assert hold_spans(np.array([1.0, 0.0, 0.0, 0.95, 0.0])) == (1, 3)
    assert hold_spans(np.array([HOLD_MAX])) == (None, None)  # at the threshold: open


def test_steps_from_stride_passes_through_the_stride_actions() -> None:
    rng = np.random.default_rng(0)
    state = rng.normal(size=14)
    stride = rng.normal(size=(SPEC.frames, 14))
    steps = steps_from_stride(stride, state, SPEC)
    assert steps.shape == (SPEC.executed_steps, 14)
    np.testing.assert_allclose(steps[SPEC.stride - 1 :: SPEC.stride], stride, atol=1e-12)
    np.testing.assert_allclose(steps[0], state + (stride[0] - state) / SPEC.stride, atol=1e-12)


def _moving_chunk(grip_now: float, grip_cmd: float) -> tuple[np.ndarray, np.ndarray]:
    state = HOME_Q14.astype(np.float64).copy()
    state[LEFT_GRIP] = grip_now
    stride = np.repeat(state[None], SPEC.frames, 0)
    stride[:, LEFT_ARM.start] += np.linspace(0.0, -0.4, SPEC.frames)  # the base joint swings the arm inwards
    stride[:, LEFT_GRIP] = grip_cmd
    return state, stride


def test_open_grippers_carry_nothing(rig32: RigConfig) -> None:
    builder = LayerBuilder(rig32)
    state, stride = _moving_chunk(1.0, 1.0)
    images = {v: np.full((32, 32, 3), 128, np.uint8) for v in rig32.cameras}
    layers = builder(images, state, stride)
    assert layers.holding.sum() == 0 and layers.released.sum() == 0
    for side in ("left", "right"):
        for v in rig32.cameras:
            assert not layers.carry_valid[side][v].any()
    assert layers.parts["cam_high"].shape == (SPEC.frames, 32, 32)
    assert layers.prior["cam_high"].shape == (SPEC.frames, 32, 32, 3)


def test_a_held_blob_follows_the_tool_in_the_head_view(rig32: RigConfig) -> None:
    rig = RigConfig.model_validate({**rig32.model_dump(), "image_size": {"width": 128, "height": 128}})
    builder = LayerBuilder(rig)
    state, stride = _moving_chunk(0.3, 0.0)  # resting on something, commanded closed
    cam = rig.head_camera_model
    tcp = rig.kinematics.tcp_poses(
        np.concatenate(
            [state[None], builder({v: np.zeros((128, 128, 3), np.uint8) for v in rig.cameras}, state, stride).poses]
        )
    )[:, 0, :3, 3]
    uv, _ = cam.project(tcp)
    images = {v: np.zeros((128, 128, 3), np.uint8) for v in rig.cameras}
    u0, v0 = np.round(uv[0]).astype(int)
    images["cam_high"][v0 - 2 : v0 + 3, u0 - 2 : u0 + 3] = (255, 0, 0)  # a red blob at the tool point now
    layers = builder(images, state, stride)
    assert layers.holding[:, 0].all() and not layers.holding[:, 1].any()
    uk, vk = np.round(uv[-1]).astype(int)
    assert np.hypot(uk - u0, vk - v0) > 6, "the test chunk must move the tool visibly"
    last = layers.carry["left"]["cam_high"][-1]
    assert layers.carry_valid["left"]["cam_high"][-1, vk, uk]
    assert last[vk, uk, 0] > 200 and last[vk, uk, 1] < 50  # the blob arrived with the tool
    assert last[v0, u0, 0] < 50  # and left its old place
    # the holding arm's own wrist view keeps what it holds where it is
    np.testing.assert_array_equal(layers.carry["left"]["cam_left_wrist"][-1], images["cam_left_wrist"])


def test_release_freezes_the_carried_layer(rig32: RigConfig) -> None:
    builder = LayerBuilder(rig32)
    state, stride = _moving_chunk(0.3, 0.0)
    stride[8:, LEFT_GRIP] = 1.0  # opens at frame 9
    images = {v: np.random.default_rng(1).integers(0, 255, (32, 32, 3), dtype=np.uint8) for v in rig32.cameras}
    layers = builder(images, state, stride)
    assert layers.released[:, 0].sum() > 0 and layers.holding[-1, 0] == 0
    head = layers.carry["left"]["cam_high"]
    np.testing.assert_array_equal(head[-1], head[-2])  # frozen where it was let go


def test_bad_shapes_are_refused(rig32: RigConfig) -> None:
    builder = LayerBuilder(rig32)
    with pytest.raises(ValueError, match="layers"):
        builder({v: np.zeros((32, 32, 3), np.uint8) for v in rig32.cameras}, np.zeros(13), np.zeros((15, 14)))


def test_memory_remembers_what_the_robot_covers_now(rig32: RigConfig) -> None:
    """A pixel under the arm now, seen free in a history frame, is in the memory with that frame's colour."""
    builder = LayerBuilder(rig32)
    state, stride = _moving_chunk(1.0, 1.0)
    now = builder.gamma.renderer.render(state[None], depth=False, shaded=False).parts["cam_high"][0]  # type: ignore[union-attr]
    earlier = state.copy()
    earlier[LEFT_ARM.start] += 0.5  # the arm was elsewhere
    then = builder.gamma.renderer.render(earlier[None], depth=False, shaded=False).parts["cam_high"][0]  # type: ignore[union-attr]
    covered_now_free_then = (now > 0) & (then == 0)
    assert covered_now_free_then.sum() > 3
    current = {v: np.full((32, 32, 3), 100, np.uint8) for v in rig32.cameras}
    history = {"cam_high": np.full((2, 32, 32, 3), 7, np.uint8)}
    history["cam_high"][1] = 200
    states = np.stack([earlier, earlier])
    layers = builder(current, state, stride, history, states, np.array([True, True]))
    mem, ok = layers.memory["cam_high"], layers.memory_valid["cam_high"]
    # the latest history frame wins where the current frame shows the robot; elsewhere the current frame
    assert ok[covered_now_free_then].mean() > 0.5
    assert (mem[ok & covered_now_free_then] == 200).all()
    far = (now == 0) & (then == 0)
    assert (mem[far & ok] == 100).mean() > 0.9
    assert not layers.memory_valid["cam_left_wrist"].any()  # moving cameras keep no memory
    # without history states the memory is the current frame's robot-free pixels only
    bare = builder(current, state, stride, history, None, None)
    assert not bare.memory_valid["cam_high"][now > 0].any()


def test_the_hand_region_follows_the_tool_path(rig32: RigConfig) -> None:
    rig = RigConfig.model_validate({**rig32.model_dump(), "image_size": {"width": 128, "height": 128}})
    builder = LayerBuilder(rig)
    state, stride = _moving_chunk(1.0, 1.0)
    layers = builder({v: np.zeros((128, 128, 3), np.uint8) for v in rig.cameras}, state, stride)
    hands = layers.hands["cam_high"]
    tcp = rig.kinematics.tcp_poses(np.concatenate([state[None], layers.poses]))[:, 0, :3, 3]
    uv, _ = rig.head_camera_model.project(tcp)
    for k in (0, 7, 14):
        u, v = np.round(uv[k + 1]).astype(int)
        if 0 <= u < 128 and 0 <= v < 128:
            assert hands[k, v, u]  # the tool point of frame k is inside its region
    assert hands[-1].sum() >= hands[0].sum()  # the region grows along the path
    assert hands[-1].mean() < 0.5  # and is not the whole image
    assert layers.hands["cam_left_wrist"].all()  # moving views are free everywhere
