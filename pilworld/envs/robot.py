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
from hw_drivers.safety import SafetyFilter, SafetyLimits
from pilworld.envs.base import EnvError, as_chunk
from pilworld.types import ActionChunk, ChunkSpec, Observation, Segment, Start


def robot_safety_filter(robot: Robot, limits: SafetyLimits | None = None) -> SafetyFilter:
    """The safety filter for ``robot``: its clock (when it has one) and its ``stop()`` on a refusal."""
    clock = getattr(robot, "clock", None)
    stop = getattr(robot, "stop", None)
    return SafetyFilter(
        robot.spec,
        limits,
        clock=clock if callable(clock) else None,
        on_violation=stop if callable(stop) else None,
        device=f"safety filter ({type(robot).__name__})",
    )


class RobotEnv:
    """The real branch over any robot (real hardware, the simulated rig, a protocol fake)."""

    def __init__(
        self,
        robot: Robot,
        spec: ChunkSpec | None = None,
        *,
        safety: SafetyFilter | None = None,
        pace: bool = True,
    ) -> None:
        self.robot = robot
        self._spec = spec or ChunkSpec()
        self.safety = safety or robot_safety_filter(robot)
        self.pace = pace
        self._obs: Observation | None = None

    @property
    def origin(self) -> str:
        return "real"

    @property
    def spec(self) -> ChunkSpec:
        return self._spec

    def reset(self, start: Start) -> Observation:
        """Check the robot stands at ``start`` (the safety filter's start-pose gate) and return the start itself.

        The start observation is returned unchanged, not re-observed, so both branches hand the policy
        byte-identical first images.
        """
        state = np.asarray(self.robot.observe().state, dtype=np.float64)
        self.safety.check_start(state, np.asarray(start.observation.state, dtype=np.float64))
        self._obs = start.observation
        return start.observation

    def step(self, chunk: ActionChunk | NDArray[np.floating]) -> Segment:
        if self._obs is None:
            raise EnvError("step() before reset(): call reset(start) first")
        spec = self._spec
        c = as_chunk(chunk, spec, self.robot.spec.dof)
        self.safety.check_observation(self._obs.timestamp)
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
