"""One subtask on the simulated rig in closed loop, recorded at the world model's stride.

What is recorded, and at which rate (see ``docs/sim_rig.md``): the robot runs at the control rate
(30 Hz); every Δ-th control step (10 Hz) we keep the observation (all three views and the measured
state) and, as that frame's action, the command whose effect the *next* stored frame shows — the
stride-aligned action ``a[t + Δ − 1]``. A stored episode is therefore the paper's clip structure
with stride 1: frame ``i`` is control step ``iΔ``, action ``i`` is the stride-aligned action of the
step ``(i+1)Δ − 1``; nothing the world model conditions on is lost, and rendering costs a third.
The full-rate commands of each round are kept too (``commands``), for diagnostics.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray

from pilworld.types import ActionChunk, ChunkSpec, Observation
from simrig.robot import SimRobot, SubtaskCheck

PolicyFn = Callable[[Observation, str], NDArray[np.floating]]


@dataclass
class SubtaskRecording:
    """Frames at stride Δ of one subtask, with the stride-aligned actions and the checker's verdict."""

    subtask_index: int
    instruction: str
    images: dict[str, list[NDArray[np.uint8]]] = field(default_factory=dict)
    states: list[NDArray[np.float32]] = field(default_factory=list)
    actions: list[NDArray[np.float32]] = field(default_factory=list)
    rounds: list[int] = field(default_factory=list)
    commands: list[NDArray[np.float32]] = field(default_factory=list)  # every control step
    check: SubtaskCheck | None = None
    last: Observation | None = None  # the final observation (where a following subtask starts)

    def add_frame(self, obs: Observation, round_index: int) -> None:
        for view, image in obs.images.items():
            self.images.setdefault(view, []).append(np.asarray(image))
        self.states.append(np.asarray(obs.state, dtype=np.float32))
        self.rounds.append(round_index)

    @property
    def length(self) -> int:
        return len(self.states)


def run_subtask(
    robot: SimRobot,
    policy: PolicyFn,
    start: Observation,
    instruction: str,
    *,
    spec: ChunkSpec | None = None,
    record: bool = True,
    subtask_index: int = 0,
) -> SubtaskRecording:
    """``spec.rounds`` closed-loop rounds from ``start``: query, execute K·Δ steps, observe; then judge.

    With ``record`` every Δ-th observation is rendered and kept; without it only the observation the
    policy needs at the end of each round is rendered (for success-rate benchmarks).
    """
    spec = spec or ChunkSpec()
    stride = spec.stride
    rec = SubtaskRecording(subtask_index=subtask_index, instruction=instruction)
    obs = start
    if record:
        rec.add_frame(obs, 0)
    for r in range(spec.rounds):
        chunk = ActionChunk.from_array(policy(obs, instruction), name="policy")
        if chunk.dim != robot.spec.dof:
            raise ValueError(f"policy: expected {robot.spec.dof} action dimensions, got {chunk.dim}")
        for step, action in enumerate(chunk.executed(spec)):
            sent = robot.send_action(action)
            rec.commands.append(sent)
            if record and (step + 1) % stride == 0:
                rec.actions.append(sent)  # the stride-aligned action that led to the frame added next
                obs = robot.observe()
                rec.add_frame(obs, r)
        if not record:
            obs = robot.observe()
    rec.last = obs
    if record:
        rec.actions.append(rec.commands[-1])  # the last frame has no successor: repeat the last command
    rec.check = robot.check_subtask(subtask_index)
    return rec
