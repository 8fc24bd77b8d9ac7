"""Where the robot will *be*, not where it was told to go: the servo lag of the render and the prior.

A position-controlled arm trails its command: the simulated rig's stiff servo with the UR's speed limit
(and a real UR's ``servoJ`` with its lookahead) reaches each commanded joint vector about one control
step later. The paper's Γ draws the commanded stride-aligned actions; Γ⁺'s robot render and scene prior
are pixel-exact, so they place the arm and the wrist cameras at the commands delayed by the rig's
``control_lag_steps`` ``d``: frame k (k = 1 … K) gets the chunk at control step ``kΔ − d`` — rows
``kΔ − 1 − d`` of the 0-based chunk, linearly interpolated for a fractional ``d``, the state before the
chunk where that falls before row 0. ``d = 0`` is exactly the stride-aligned actions.

:func:`estimate_lag` fits ``d`` from recorded rounds (commands sent, measured joints at the frames):
``pilworld bench reprojection`` reports it, and a user sets ``control_lag_steps`` in the rig config from it.
"""

from __future__ import annotations

from typing import Any

import numpy as np
from numpy.typing import NDArray

from pilworld.types import LEFT_ARM, RIGHT_ARM, STATE_DIM, ChunkSpec

_ARM_JOINTS = np.r_[LEFT_ARM.start : LEFT_ARM.stop, RIGHT_ARM.start : RIGHT_ARM.stop]


def lagged_poses(
    chunk: NDArray[np.floating],
    previous_state: NDArray[np.floating] | None,
    spec: ChunkSpec,
    lag_steps: float,
) -> NDArray[np.float64]:
    """(H, 14) chunk → (K, 14) joint vectors at control steps ``kΔ − lag_steps`` (see the module docstring).

    Without ``previous_state``, steps before the chunk take its first row.
    """
    c = np.asarray(chunk, dtype=np.float64)
    if c.ndim != 2 or c.shape[1] != STATE_DIM or c.shape[0] < spec.executed_steps:
        raise ValueError(f"chunk: expected ({spec.executed_steps}+, {STATE_DIM}), got shape {c.shape}")
    lag = float(lag_steps)
    if not (np.isfinite(lag) and 0.0 <= lag <= spec.executed_steps):
        raise ValueError(
            f"lag_steps: expected a finite number of control steps in [0, {spec.executed_steps}], got {lag_steps!r}"
        )
    first = c[:1] if previous_state is None else np.asarray(previous_state, dtype=np.float64).reshape(1, STATE_DIM)
    seq = np.concatenate([first, c])  # seq[i] = the joints after control step i (0 = before the chunk)
    pos = np.arange(1, spec.frames + 1) * spec.stride - lag
    lo = np.clip(np.floor(pos).astype(np.int64), 0, seq.shape[0] - 1)
    hi = np.minimum(lo + 1, seq.shape[0] - 1)
    w = np.clip(pos - lo, 0.0, 1.0)[:, None]
    out: NDArray[np.float64] = seq[lo] * (1.0 - w) + seq[hi] * w
    return out


def estimate_lag(
    commands: NDArray[np.floating],
    states_before: NDArray[np.floating],
    measured: NDArray[np.floating],
    spec: ChunkSpec,
    candidates: NDArray[np.floating] | None = None,
) -> dict[str, Any]:
    """Fit ``control_lag_steps`` to recorded rounds: the candidate lag with the least arm-joint error.

    ``commands`` (N, KΔ, 14): the commands sent in each round; ``states_before`` (N, 14): the measured
    joints before it; ``measured`` (N, K, 14): the measured joints at its K frames. Returns the best lag
    and the mean absolute joint error (degrees) per candidate (default 0, 0.25, …, 4 steps).
    """
    cmd = np.asarray(commands, dtype=np.float64)
    before = np.asarray(states_before, dtype=np.float64)
    meas = np.asarray(measured, dtype=np.float64)
    if (
        cmd.ndim != 3
        or before.shape != (cmd.shape[0], STATE_DIM)
        or meas.shape != (cmd.shape[0], spec.frames, STATE_DIM)
    ):
        raise ValueError(
            f"estimate_lag: expected commands (N, {spec.executed_steps}, 14), states_before (N, 14), measured "
            f"(N, {spec.frames}, 14); got {cmd.shape}, {before.shape}, {meas.shape}"
        )
    lags = np.arange(0.0, 4.01, 0.25) if candidates is None else np.asarray(candidates, dtype=np.float64)
    errors = []
    for lag in lags:
        pred = np.stack([lagged_poses(c, b, spec, float(lag)) for c, b in zip(cmd, before, strict=True)])
        errors.append(float(np.degrees(np.mean(np.abs(pred - meas)[..., _ARM_JOINTS]))))
    best = int(np.argmin(errors))
    return {
        "best_lag_steps": float(lags[best]),
        "mean_abs_joint_error_deg": dict(zip((f"{v:g}" for v in lags), errors, strict=True)),
        "rounds": int(cmd.shape[0]),
    }
