"""Moving a hardware rig's arm between calibration poses: capped speed, collision-checked paths, the safety filter.

A calibration moves one arm through planned poses while a person may stand beside the rig, so every move is:

* **checked before it starts** (:func:`path_problem`): the straight joint-space path from where the arm stands
  to the pose is sampled; every joint origin and the TCP must stay above the table and the two arms' capsules
  (:mod:`.occlusion`) must stay ``arm_gap_m`` apart. When the direct path fails, a path through the pose the
  collection started from (the hold pose) is tried; when that fails too the pose is skipped and reported;
* **paced** at the control rate (:func:`paced_move`): a cosine profile whose peak joint speed is at most
  ``speed`` rad/s (for a calibration, far below the arm's limit), every command through the rig's
  :class:`~hw_drivers.safety.SafetyFilter` (joint limits, per-step cap, speed cap), the other arm and the
  grippers holding their state;
* **settled** before a frame is taken: the goal is held for ``settle_s`` and until the measured joints are within
  ``settle_tol_rad`` of it (the measured state is what FK uses, so a small tracking error costs nothing).
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable
from dataclasses import dataclass
from typing import Protocol

import numpy as np
import numpy.typing as npt

from hw_drivers.safety import SafetyFilter
from pilworld.calibration.occlusion import arm_capsules, segment_distances
from pilworld.kinematics.dual_arm import DualArmKinematics
from pilworld.kinematics.fk import fk_frames
from pilworld.types import ARM_LAYOUT, ARM_SIDES, STATE_DIM

__all__ = ["MoveSettings", "move_duration", "paced_move", "path_problem"]

FloatArray = npt.NDArray[np.float64]


@dataclass(frozen=True)
class MoveSettings:
    """How a calibration moves the arm; validated on construction."""

    speed: float = 0.5  #: top joint speed of a move, rad/s
    min_duration_s: float = 1.5  #: no move is quicker than this
    settle_s: float = 0.5  #: the goal is held this long before a frame is taken
    settle_tol_rad: float = 0.005  #: … and until the measured joints are this close to it
    settle_timeout_s: float = 5.0  #: a warning (not an error) when the arm is not settled by then
    path_samples: int = 25  #: configurations checked along a path
    table_clearance_m: float = 0.04  #: joint origins stay this far above the table
    tcp_clearance_m: float = 0.08  #: the TCP (and the board beside it) stays this far above the table
    arm_gap_m: float = 0.02  #: the two arms' capsules (already generous, see .occlusion) stay this far apart

    def __post_init__(self) -> None:
        if not 0.0 < self.speed <= 1.0:
            raise ValueError(f"--speed: expected 0 < speed <= 1.0 rad/s for a calibration move, got {self.speed}")
        for name in ("min_duration_s", "settle_s", "settle_tol_rad", "settle_timeout_s"):
            if not getattr(self, name) > 0:
                raise ValueError(f"move setting {name}: expected > 0, got {getattr(self, name)}")
        if self.path_samples < 2:
            raise ValueError(f"move setting path_samples: expected >= 2, got {self.path_samples}")


def move_duration(start: npt.ArrayLike, goal: npt.ArrayLike, settings: MoveSettings) -> float:
    """Seconds of a move from ``start`` to ``goal`` (14-d): the cosine profile peaks at π/2 × the mean speed."""
    d = np.abs(np.asarray(goal, dtype=np.float64) - np.asarray(start, dtype=np.float64))
    arms = np.concatenate([d[ARM_LAYOUT[s][0]] for s in ARM_SIDES])
    return max(settings.min_duration_s, float(arms.max()) / settings.speed * math.pi / 2.0)


def _configuration_problem(kinematics: DualArmKinematics, q14: FloatArray, settings: MoveSettings) -> str | None:
    capsules = {}
    for side in ARM_SIDES:
        mount = getattr(kinematics, side)
        q = q14[ARM_LAYOUT[side][0]]
        frames = mount.T_rig_base @ fk_frames(q, mount.dh)
        if frames[1:, 2, 3].min() < settings.table_clearance_m:
            return f"the {side} arm's joints come within {settings.table_clearance_m * 100:.0f} cm of the table"
        if (frames[6] @ mount.T_flange_tcp)[2, 3] < settings.tcp_clearance_m:
            return f"the {side} gripper comes within {settings.tcp_clearance_m * 100:.0f} cm of the table"
        capsules[side] = arm_capsules(mount, q)
    left, right = capsules["left"], capsules["right"]
    dist = segment_distances(left.start, left.end, right.start, right.end)
    gap = dist - left.radius[:, None] - right.radius[None, :]
    if gap.min() < settings.arm_gap_m:
        return f"the two arms come within {max(gap.min(), 0.0) * 100:.1f} cm of each other"
    return None


def path_problem(
    kinematics: DualArmKinematics, start: npt.ArrayLike, goal: npt.ArrayLike, settings: MoveSettings
) -> str | None:
    """Why the straight joint-space path ``start`` → ``goal`` (14-d) is unsafe, or None when it is clear."""
    a = np.asarray(start, dtype=np.float64).reshape(STATE_DIM)
    b = np.asarray(goal, dtype=np.float64).reshape(STATE_DIM)
    for s in np.linspace(0.0, 1.0, settings.path_samples):
        problem = _configuration_problem(kinematics, a + (b - a) * s, settings)
        if problem is not None:
            return f"{problem} ({s:.0%} of the way)"
    return None


class StreamingRobot(Protocol):
    """What a paced move needs of a robot (``DualArmRobot`` has both)."""

    def send_action(self, action: npt.NDArray[np.floating]) -> npt.NDArray[np.float32]: ...

    def state(self) -> npt.NDArray[np.float32]: ...


def paced_move(
    robot: StreamingRobot,
    safety: SafetyFilter,
    start: npt.ArrayLike,
    goal: npt.ArrayLike,
    settings: MoveSettings,
    *,
    rate_hz: float,
    sleep: Callable[[float], None] = time.sleep,
    clock: Callable[[], float] = time.monotonic,
) -> FloatArray:
    """Stream a capped-speed cosine profile ``start`` → ``goal`` through ``safety``, hold, settle; the measured state.

    ``robot`` has ``send_action(14-d)`` and ``state()`` (a :class:`hw_drivers.robot.Robot`). Commands are sent
    every ``1 / rate_hz`` seconds. Raises what the safety filter or the robot raises (both stop the arms first).
    """
    a = np.asarray(start, dtype=np.float64).reshape(STATE_DIM)
    b = np.asarray(goal, dtype=np.float64).reshape(STATE_DIM)
    period = 1.0 / rate_hz
    steps = max(1, math.ceil(move_duration(a, b, settings) * rate_hz))
    send = robot.send_action
    tick = clock()

    def wait() -> None:
        nonlocal tick
        tick += period
        pause = tick - clock()
        if pause > 0:
            sleep(pause)
        else:
            tick = clock()  # behind: do not try to catch up with a burst of commands

    for k in range(1, steps + 1):
        s = 0.5 - 0.5 * math.cos(math.pi * k / steps)
        send(safety(a + (b - a) * s))
        wait()
    hold_until = clock() + settings.settle_s
    give_up = clock() + settings.settle_timeout_s
    state = np.asarray(robot.state(), dtype=np.float64)
    moving = np.concatenate([np.arange(STATE_DIM)[ARM_LAYOUT[side][0]] for side in ARM_SIDES])
    while True:
        send(safety(b))
        wait()
        state = np.asarray(robot.state(), dtype=np.float64)
        settled = float(np.max(np.abs(state[moving] - b[moving]))) <= settings.settle_tol_rad
        now = clock()
        if (now >= hold_until and settled) or now >= give_up:
            return state
