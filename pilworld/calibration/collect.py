"""Move a ``Robot`` through planned board poses and capture a head-camera image at each.

Works with any ``hw_drivers.robot.Robot``: the arm is commanded one control step at a time
(``send_action``) along a smooth (cosine) joint-space profile from its measured state to the IK target,
slow enough that no joint exceeds ``speed_fraction`` of its speed limit, while the other arm and both
grips hold the state measured when the collection started. After ``settle_s`` of holding the target,
the *measured* state (``observe().state``, not the command) is recorded with a frame from ``capture``
(the head camera at calibration resolution: the simulator renders it, a real rig grabs a full frame).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import Final

import numpy as np
import numpy.typing as npt

from hw_drivers.robot import Robot
from pilworld.calibration.plan import PosePlan
from pilworld.calibration.recording import RecordedView
from pilworld.types import ARM_LAYOUT, STATE_DIM

__all__ = ["collect_views", "move_to"]

FloatArray = npt.NDArray[np.float64]

#: Joint speed assumed when the robot reports no limit (rad/s; grips: full strokes per second).
DEFAULT_JOINT_SPEED: Final = 1.0
#: A warning is printed when the settled arm is farther than this from its target (rad).
TRACKING_WARN_RAD: Final = 0.01


def move_to(
    robot: Robot,
    target: npt.ArrayLike,
    *,
    min_duration_s: float = 1.5,
    settle_s: float = 0.5,
    speed_fraction: float = 0.5,
) -> FloatArray:
    """Drive ``robot`` smoothly to the 14-d ``target``, hold it ``settle_s``; returns the measured state."""
    spec = robot.spec
    goal = np.asarray(target, dtype=np.float64).reshape(STATE_DIM)
    start = np.asarray(robot.observe().state, dtype=np.float64)
    speeds = np.asarray(spec.max_joint_speed or [DEFAULT_JOINT_SPEED] * STATE_DIM, dtype=np.float64)
    # A cosine profile peaks at π/2 times the mean speed.
    needed = float(np.max(np.abs(goal - start) / (speed_fraction * speeds))) * math.pi / 2.0
    rate = spec.control_rate_hz
    steps = max(1, math.ceil(max(min_duration_s, needed) * rate))
    for k in range(1, steps + 1):
        s = 0.5 - 0.5 * math.cos(math.pi * k / steps)
        robot.send_action(start + (goal - start) * s)
    for _ in range(math.ceil(settle_s * rate)):
        robot.send_action(goal)
    return np.asarray(robot.observe().state, dtype=np.float64)


def collect_views(
    robot: Robot,
    plan: PosePlan,
    capture: Callable[[], npt.NDArray[np.uint8]],
    *,
    min_duration_s: float = 1.5,
    settle_s: float = 0.5,
    log: Callable[[str], None] | None = None,
) -> list[RecordedView]:
    """Visit every pose of ``plan`` in order; one :class:`RecordedView` (image + measured state) per pose."""
    hold = np.asarray(robot.observe().state, dtype=np.float64)
    arm = ARM_LAYOUT[plan.arm][0]
    views = []
    for i, command in enumerate(plan.states(hold)):
        state = move_to(robot, command, min_duration_s=min_duration_s, settle_s=settle_s)
        error = float(np.max(np.abs(state[arm] - command[arm])))
        if log is not None and error > TRACKING_WARN_RAD:
            off = math.degrees(error)
            log(f"pose {i}: the {plan.arm} arm settled {off:.2f}° from its target (FK uses the measured state)")
        image = np.asarray(capture(), dtype=np.uint8)
        views.append(RecordedView(name=f"{plan.arm}_{i:03d}", arm=plan.arm, image=image, state=state, command=command))
    if log is not None:
        log(f"collected {len(views)} views with the {plan.arm} arm")
    return views
