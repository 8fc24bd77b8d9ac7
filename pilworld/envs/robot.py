"""The real branch: a :class:`~hw_drivers.robot.Robot` executing the first K·Δ steps of each chunk.

Every step goes through a safety filter before it reaches the robot, at the control rate, and a frame
is observed every Δ steps. What is recorded as a step's action is what the robot reports it sent
(``send_action``'s return value), so the stored episode shows the truth rather than the request.

Pacing: a real arm must receive one command per control period; ``pace=True`` (the default, safe for
hardware) sleeps to the control clock. The simulated rig advances physics synchronously and runs
faster than real time with ``pace=False``.
"""

from __future__ import annotations

import time

import numpy as np
from numpy.typing import NDArray

from hw_drivers.robot import Robot
from pilworld.envs.base import EnvError, as_chunk
from pilworld.types import ActionChunk, ChunkSpec, Observation, RobotSpec, Segment, Start


class LimitFilter:
    """The minimal safety filter: refuse non-finite commands, clip to joint limits and joint speed.

    The speed limit is relative to the previous filtered command (the robot's measured state at reset),
    so a chunk that jumps is slowed down instead of slamming the arm. Issue #8 adds workspace and
    collision checks behind the same ``__call__`` / ``reset`` interface.
    """

    def __init__(self, spec: RobotSpec) -> None:
        self.spec = spec
        self._lower = spec.lower_array.astype(np.float64)
        self._upper = spec.upper_array.astype(np.float64)
        self._step = (
            np.asarray(spec.max_joint_speed, dtype=np.float64) / spec.control_rate_hz if spec.max_joint_speed else None
        )
        self._last: NDArray[np.float64] | None = None

    def reset(self, state: NDArray[np.floating]) -> None:
        self._last = np.asarray(state, dtype=np.float64).copy()

    def __call__(self, action: NDArray[np.floating]) -> NDArray[np.float32]:
        a = np.asarray(action, dtype=np.float64)
        if a.shape != (self.spec.dof,):
            raise ValueError(f"action: expected shape ({self.spec.dof},), got {a.shape}")
        if not np.all(np.isfinite(a)):
            raise ValueError(f"action: must be finite, got {a.tolist()}")
        a = np.clip(a, self._lower, self._upper)
        if self._step is not None and self._last is not None:
            a = np.clip(a, self._last - self._step, self._last + self._step)
        self._last = a
        return a.astype(np.float32)


class RobotEnv:
    """The real branch over any robot (real hardware, the simulated rig, a protocol fake)."""

    def __init__(
        self,
        robot: Robot,
        spec: ChunkSpec | None = None,
        *,
        safety: LimitFilter | None = None,
        pace: bool = True,
        start_tolerance: float = 0.02,
    ) -> None:
        self.robot = robot
        self._spec = spec or ChunkSpec()
        self.safety = safety or LimitFilter(robot.spec)
        self.pace = pace
        self.start_tolerance = start_tolerance
        self._obs: Observation | None = None

    @property
    def origin(self) -> str:
        return "real"

    @property
    def spec(self) -> ChunkSpec:
        return self._spec

    def reset(self, start: Start) -> Observation:
        """Check the robot stands at ``start`` (within ``start_tolerance`` rad) and return the start itself.

        The start observation is returned unchanged, not re-observed, so both branches hand the policy
        byte-identical first images.
        """
        state = np.asarray(self.robot.observe().state, dtype=np.float64)
        want = np.asarray(start.observation.state, dtype=np.float64)
        if state.shape != want.shape:
            raise EnvError(f"robot state has shape {state.shape}, the start's has {want.shape}")
        err = np.abs(state - want)
        if float(err.max()) > self.start_tolerance:
            j = int(err.argmax())
            raise EnvError(
                f"the robot is not at the start: {self.robot.spec.joint_names[j]} differs by {err[j]:.4f} "
                f"(tolerance {self.start_tolerance}); move it to the start before running the branch"
            )
        self.safety.reset(state)
        self._obs = start.observation
        return start.observation

    def step(self, chunk: ActionChunk | NDArray[np.floating]) -> Segment:
        if self._obs is None:
            raise EnvError("step() before reset(): call reset(start) first")
        spec = self._spec
        c = as_chunk(chunk, spec, self.robot.spec.dof)
        period = 1.0 / self.robot.spec.control_rate_hz
        sent: list[NDArray[np.float32]] = []
        frames: list[Observation] = []
        t_next = time.monotonic()
        for i, action in enumerate(c.executed(spec)):
            if self.pace:
                delay = t_next - time.monotonic()
                if delay > 0:
                    time.sleep(delay)
                t_next += period
            sent.append(np.asarray(self.robot.send_action(self.safety(action)), dtype=np.float32))
            if (i + 1) % spec.stride == 0:
                frames.append(self.robot.observe())
        segment = Segment(observations=tuple(frames), actions=np.stack(sent), stride=spec.stride)
        self._obs = segment.last
        return segment
