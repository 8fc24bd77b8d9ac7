"""The data contract: constructors accept good data and name the field of bad data."""

from __future__ import annotations

import numpy as np
import pytest

from pilworld.types import (
    ActionChunk,
    ChunkSpec,
    Observation,
    RobotSpec,
    Segment,
    Start,
    Subtask,
    dual_arm_joint_names,
)


def _obs(t: float = 0.0, views: tuple[str, ...] = ("cam_high", "cam_left_wrist")) -> Observation:
    return Observation(
        images={v: np.zeros((8, 6, 3), np.uint8) for v in views}, state=np.zeros(14, np.float32), timestamp=t
    )


def test_observation_is_immutable_copy() -> None:
    img = np.zeros((8, 6, 3), np.uint8)
    state = np.arange(14, dtype=np.float32)
    obs = Observation(images={"cam_high": img}, state=state, timestamp=1)
    img[:] = 7
    state[:] = -1
    assert obs.images["cam_high"].max() == 0 and obs.state[3] == 3
    assert obs.timestamp == 1.0 and isinstance(obs.timestamp, float)
    assert obs.image_size("cam_high") == (6, 8)
    with pytest.raises(ValueError, match="read-only"):
        obs.state[0] = 5
    with pytest.raises(TypeError):
        obs.images["other"] = img  # type: ignore[index]


@pytest.mark.parametrize(
    ("kwargs", "message"),
    [
        ({"images": {}}, "images: expected a non-empty mapping"),
        (
            {"images": {"cam_high": np.zeros((8, 6, 3), np.float32)}},
            r"images\['cam_high'\]: expected dtype uint8",
        ),
        (
            {"images": {"cam_high": np.zeros((8, 6), np.uint8)}},
            r"images\['cam_high'\]: expected shape \(H, W, 3\)",
        ),
        ({"images": {"cam_high": [[0]]}}, r"images\['cam_high'\]: expected a numpy uint8 array"),
        ({"state": np.zeros(14)}, "state: expected dtype float32, got float64"),
        ({"state": np.zeros((2, 7), np.float32)}, r"state: expected shape \(N\), got \(2, 7\)"),
        ({"state": np.array([0, np.nan], np.float32)}, "state: values must be finite, got nan at index 1"),
        ({"timestamp": float("inf")}, "timestamp: must be finite"),
        ({"timestamp": "now"}, "timestamp: expected a number"),
    ],
)
def test_observation_rejects_bad_fields(kwargs: dict[str, object], message: str) -> None:
    good: dict[str, object] = {
        "images": {"cam_high": np.zeros((8, 6, 3), np.uint8)},
        "state": np.zeros(14, np.float32),
        "timestamp": 0.0,
    }
    with pytest.raises(ValueError, match=message):
        Observation(**{**good, **kwargs})  # type: ignore[arg-type]


def test_observation_from_raw_casts_state() -> None:
    obs = Observation.from_raw({"cam_high": np.zeros((2, 2, 3), np.uint8)}, [0.5] * 14, 0.0)
    assert obs.state.dtype == np.float32
    with pytest.raises(ValueError, match="state: expected numbers"):
        Observation.from_raw({"cam_high": np.zeros((2, 2, 3), np.uint8)}, ["a"] * 14, 0.0)


def test_chunk_spec_defaults_and_stride_indices() -> None:
    spec = ChunkSpec()
    assert (spec.horizon, spec.frames, spec.stride, spec.history, spec.rounds) == (50, 15, 3, 5, 5)
    assert spec.executed_steps == 45
    idx = spec.stride_indices()
    assert idx[0] == 2 and idx[-1] == 44 and len(idx) == 15  # a_{t+Δ} … a_{t+KΔ}, 0-based
    with pytest.raises(ValueError, match="K·Δ ≤ H_π"):
        ChunkSpec(horizon=40)
    with pytest.raises(ValueError, match="stride: expected an integer >= 1"):
        ChunkSpec(stride=0)


def test_action_chunk_stride_aligned_rows() -> None:
    a = np.arange(50, dtype=np.float32)[:, None].repeat(14, axis=1)
    chunk = ActionChunk(a)
    sa = chunk.stride_aligned(ChunkSpec())
    assert sa.shape == (15, 14)
    np.testing.assert_array_equal(sa[:, 0], np.arange(2, 45, 3))
    assert chunk.executed(ChunkSpec()).shape == (45, 14)
    with pytest.raises(ValueError, match="45 are needed"):
        ActionChunk(a[:44]).stride_aligned(ChunkSpec())


def test_action_chunk_from_array_casts_and_validates() -> None:
    chunk = ActionChunk.from_array(np.ones((50, 14), np.float64))
    assert chunk.actions.dtype == np.float32 and chunk.horizon == 50 and chunk.dim == 14
    with pytest.raises(ValueError, match="reply: values must be finite"):
        ActionChunk.from_array(np.full((50, 14), np.inf), name="reply")
    with pytest.raises(ValueError, match="actions: expected dtype float32"):
        ActionChunk(np.ones((50, 14)))
    with pytest.raises(ValueError, match="actions: expected shape"):
        ActionChunk(np.ones(14, np.float32))


def test_segment_checks_rows_and_time_order() -> None:
    obs = (_obs(0.1), _obs(0.2))
    seg = Segment(observations=obs, actions=np.zeros((6, 14), np.float32), stride=3)
    assert seg.last is obs[1]
    with pytest.raises(ValueError, match=r"actions: expected 2 observations × stride 3 = 6 rows, got 5"):
        Segment(observations=obs, actions=np.zeros((5, 14), np.float32), stride=3)
    with pytest.raises(ValueError, match="timestamps must not decrease"):
        Segment(observations=obs[::-1], actions=np.zeros((6, 14), np.float32), stride=3)
    with pytest.raises(ValueError, match="observations: expected a non-empty"):
        Segment(observations=(), actions=np.zeros((0, 14), np.float32), stride=3)


def test_subtask_and_start_validation() -> None:
    sub = Subtask(task="sort_cubes", index=0, instruction="sort the cubes by size.", seed=3)
    start = Start(subtask=sub, observation=_obs(1.0), history=[_obs(0.0), _obs(0.5)])  # type: ignore[arg-type]
    assert len(start.history) == 2
    with pytest.raises(ValueError, match="instruction: expected a non-empty string"):
        Subtask(task="sort_cubes", index=0, instruction=" ")
    with pytest.raises(ValueError, match="index: expected an integer >= 0"):
        Subtask(task="sort_cubes", index=-1, instruction="x")
    with pytest.raises(ValueError, match=r"history\[0\]: views"):
        Start(subtask=sub, observation=_obs(1.0), history=(_obs(0.0, views=("cam_high",)),))
    with pytest.raises(ValueError, match=r"history\[0\]: timestamp 2.0 is after"):
        Start(subtask=sub, observation=_obs(1.0), history=(_obs(2.0),))


def test_robot_spec() -> None:
    names = dual_arm_joint_names()
    assert names[0] == "left_joint_1" and names[6] == "left_grip" and names[13] == "right_grip"
    spec = RobotSpec(joint_names=names, lower=(-1.0,) * 14, upper=(1.0,) * 14)
    assert spec.dof == 14
    v = np.zeros(14, np.float32)
    v[13] = 2.0
    assert spec.out_of_limits(v) == ["right_grip"]
    spec.check_state("state", v)
    with pytest.raises(ValueError, match=r"state: expected shape \(14\)"):
        spec.check_state("state", np.zeros(13, np.float32))
    with pytest.raises(ValueError, match="lower must be < upper"):
        RobotSpec(joint_names=names, lower=(1.0,) * 14, upper=(1.0,) * 14)
    with pytest.raises(ValueError, match="control_rate_hz: expected a positive rate"):
        RobotSpec(joint_names=names, lower=(-1.0,) * 14, upper=(1.0,) * 14, control_rate_hz=0.0)
