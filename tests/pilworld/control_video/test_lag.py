"""The servo-lag model of Γ⁺'s render and prior: delayed commands, and fitting the delay to recorded rounds."""

from __future__ import annotations

import numpy as np
import pytest

from pilworld.control_video.examples import random_chunks
from pilworld.control_video.lag import estimate_lag, lagged_poses
from pilworld.types import ChunkSpec

SPEC = ChunkSpec()


def test_zero_lag_is_the_stride_aligned_actions() -> None:
    chunk = random_chunks(1, SPEC.horizon, seed=3)[0]
    np.testing.assert_array_equal(lagged_poses(chunk, None, SPEC, 0.0), chunk[SPEC.stride_indices()])


def test_integer_and_fractional_lags_interpolate_rows_and_reach_back_to_the_state() -> None:
    chunk = np.arange(SPEC.horizon, dtype=np.float64)[:, None].repeat(14, axis=1)  # row i holds i
    state = np.full(14, -1.0)  # "row −1"
    out = lagged_poses(chunk, state, SPEC, 1.0)
    np.testing.assert_array_equal(out[:, 0], SPEC.stride_indices() - 1)
    out = lagged_poses(chunk, state, SPEC, 1.5)
    np.testing.assert_allclose(out[:, 0], SPEC.stride_indices() - 1.5)
    out = lagged_poses(chunk, state, SPEC, 4.0)  # frame 1 (step 3) falls before the chunk: the state
    assert out[0, 0] == -1.0 and out[1, 0] == 1.0


def test_estimate_recovers_a_known_delay() -> None:
    chunks = random_chunks(12, SPEC.horizon, seed=5).astype(np.float64)[:, : SPEC.executed_steps]
    before = chunks[:, 0] - 0.01
    measured = np.stack([lagged_poses(c, b, SPEC, 1.25) for c, b in zip(chunks, before, strict=True)])
    fit = estimate_lag(chunks, before, measured, SPEC)
    assert fit["best_lag_steps"] == 1.25
    assert fit["mean_abs_joint_error_deg"]["1.25"] < 1e-9 < fit["mean_abs_joint_error_deg"]["0"]


def test_bad_input_is_named() -> None:
    chunk = random_chunks(1, SPEC.horizon, seed=3)[0]
    with pytest.raises(ValueError, match="lag_steps"):
        lagged_poses(chunk, None, SPEC, float("nan"))
    with pytest.raises(ValueError, match="chunk"):
        lagged_poses(chunk[:30], None, SPEC, 1.0)
    with pytest.raises(ValueError, match="estimate_lag"):
        estimate_lag(chunk[None], chunk[:1], chunk[None, :14], SPEC)  # 14 frames, not K = 15
