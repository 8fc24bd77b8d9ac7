"""The safety filter in front of every robot backend (hardware, protocol fakes and the simulator).

Every command passes :meth:`SafetyFilter.__call__` before it reaches a robot. The rules, in order:

1. **shape and finiteness** — a (dof,) vector with no NaN or inf, else refused;
2. **joint limits** — a target beyond a limit by more than ``limit_margin`` is refused (a policy that
   asks for that is broken); one inside the margin is clipped onto the limit;
3. **per-step |Δq| cap** — a target farther than ``max_step`` from the previous command is refused:
   no controller should be asked to jump that far in one control period;
4. **velocity cap** — within the step cap, the command is slowed to ``spec.max_joint_speed`` (clipped
   to previous ± speed/rate, LeRobot's ``max_relative_target``), and the clipped value is what the
   robot reports it sent;
5. **start-pose gate, both sides** — :meth:`check_start`: the robot must stand at the episode's start
   pose (a robot left elsewhere is refused, not dragged there at policy speed), and the first command
   must start near where the robot stands (a policy whose chunk begins elsewhere is refused: GELLO
   checks only one side, and stale goals causing violent start-up motion are a top user complaint);
6. **stale observations** — :meth:`check_observation`: a chunk computed from an observation older than
   ``max_observation_age`` (by the robot's clock) is refused.

A refusal calls ``on_violation`` (the owner's stop: servoStop, hold position) before raising
:class:`~hw_drivers.errors.SafetyViolationError` (or ``StaleObservationError``) naming the rule and
the joint. Nothing is ever replaced by a default or a fake.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from hw_drivers.errors import SafetyViolationError, StaleObservationError
from pilworld.types import RobotSpec

ARM_SPEED = math.pi  # rad/s, a UR e-Series joint's maximum
GRIP_SPEED = 2.0  # normalised opening per second (full stroke in 0.5 s)


def dual_arm_speed_caps() -> tuple[float, ...]:
    """``RobotSpec.max_joint_speed`` of the 14-d dual-arm layout: every arm joint, then the grip, per arm."""
    return tuple([ARM_SPEED] * 6 + [GRIP_SPEED]) * 2


@dataclass(frozen=True)
class SafetyLimits:
    """The filter's thresholds; the defaults suit a UR arm at 30 Hz and normalised grippers."""

    limit_margin: float = 0.05  # rad beyond a joint limit that is clipped rather than refused
    max_arm_step: float = 0.35  # rad per control step (10 rad/s at 30 Hz): beyond this, refused
    max_grip_step: float = math.inf  # grippers open or close in one command by design
    start_tolerance: float = 0.02  # rad: the robot must be this close to the start pose
    start_command_tolerance: float = 0.25  # rad: the first command must be this close to the robot
    max_observation_age: float = 1.0  # s: a chunk from an older observation is refused

    def __post_init__(self) -> None:
        for name in (
            "limit_margin",
            "max_arm_step",
            "max_grip_step",
            "start_tolerance",
            "start_command_tolerance",
            "max_observation_age",
        ):
            value = getattr(self, name)
            if not value >= 0 or math.isnan(value):
                raise ValueError(f"{name}: expected a number >= 0, got {value!r}")


class SafetyFilter:
    """Checks and clips commands for one robot; see the module docstring for the rules.

    ``clock`` gives the robot's time in the units of its observations' timestamps (``time.monotonic``
    on hardware, simulated time in the simulator); ``None`` disables the staleness rule (the imagined
    branch, where there is no robot clock). ``on_violation`` is called before every refusal.
    """

    def __init__(
        self,
        spec: RobotSpec,
        limits: SafetyLimits | None = None,
        *,
        clock: Callable[[], float] | None = None,
        on_violation: Callable[[], None] | None = None,
        device: str = "safety filter",
    ) -> None:
        self.spec = spec
        self.limits = limits or SafetyLimits()
        self.clock = clock
        self.on_violation = on_violation
        self.device = device
        self._lower = spec.lower_array.astype(np.float64)
        self._upper = spec.upper_array.astype(np.float64)
        grip = np.array(["grip" in n for n in spec.joint_names])  # left_grip, right_grip: normalised openings
        self._max_step = np.where(grip, self.limits.max_grip_step, self.limits.max_arm_step)
        self._speed_step = (
            np.asarray(spec.max_joint_speed, dtype=np.float64) / spec.control_rate_hz if spec.max_joint_speed else None
        )
        self._arm = ~grip
        self._last: NDArray[np.float64] | None = None
        self._first = False

    # ------------------------------------------------------------------ refusals

    def _refuse(self, check: str, message: str) -> SafetyViolationError:
        self._stop()
        return SafetyViolationError(self.device, check, message)

    def _stop(self) -> None:
        if self.on_violation is not None:
            self.on_violation()

    def _joint(self, index: int) -> str:
        return self.spec.joint_names[index]

    # ------------------------------------------------------------------ episode start

    def reset(self, state: NDArray[np.floating]) -> None:
        """Start from the robot's measured ``state`` (no start-pose check; see :meth:`check_start`)."""
        s = np.asarray(state, dtype=np.float64)
        if s.shape != (self.spec.dof,) or not np.all(np.isfinite(s)):
            raise self._refuse("state", f"expected {self.spec.dof} finite values, got {s!r}")
        self._last = s.copy()
        self._first = True

    def check_start(self, measured: NDArray[np.floating], start: NDArray[np.floating]) -> None:
        """The robot side of the start-pose gate: refuse unless ``measured`` is at ``start``; then reset."""
        m = np.asarray(measured, dtype=np.float64)
        s = np.asarray(start, dtype=np.float64)
        if m.shape != s.shape:
            raise self._refuse("start_pose", f"robot state has shape {m.shape}, the start's has {s.shape}")
        gap = np.abs(m - s)
        j = int(gap.argmax())
        if float(gap[j]) > self.limits.start_tolerance:
            raise self._refuse(
                "start_pose",
                f"the robot is not at the start: {self._joint(j)} is {gap[j]:.4f} away (tolerance "
                f"{self.limits.start_tolerance}); move it to the start pose first",
            )
        self.reset(m)

    def check_observation(self, timestamp: float) -> None:
        """Refuse a chunk computed from an observation taken at ``timestamp`` if it is too old now."""
        if self.clock is None:
            return
        age = self.clock() - float(timestamp)
        if age > self.limits.max_observation_age:
            self._stop()
            raise StaleObservationError(
                self.device,
                f"the observation behind this chunk is {age:.3f} s old (limit {self.limits.max_observation_age} s)",
            )

    # ------------------------------------------------------------------ every command

    def __call__(self, action: NDArray[np.floating]) -> NDArray[np.float32]:
        a = np.asarray(action, dtype=np.float64)
        if a.shape != (self.spec.dof,):
            raise self._refuse("shape", f"expected shape ({self.spec.dof},), got {a.shape}")
        bad = ~np.isfinite(a)
        if bad.any():
            j = int(np.argmax(bad))
            raise self._refuse("finite", f"{self._joint(j)} is {a[j]!r}")
        m = self.limits.limit_margin
        over = np.maximum(self._lower - a, a - self._upper)
        j = int(over.argmax())
        if float(over[j]) > m:
            raise self._refuse(
                "joint_limits",
                f"{self._joint(j)} = {a[j]:.4f} is outside [{self._lower[j]:.4f}, {self._upper[j]:.4f}] "
                f"by {over[j]:.4f} (margin {m})",
            )
        a = np.clip(a, self._lower, self._upper)
        if self._last is not None:
            step = np.abs(a - self._last)
            if self._first:
                # The command side of the start-pose gate: the chunk must begin where the robot stands.
                gap = np.where(self._arm, step, 0.0)
                j = int(gap.argmax())
                if float(gap[j]) > self.limits.start_command_tolerance:
                    raise self._refuse(
                        "start_command",
                        f"the first command moves {self._joint(j)} by {gap[j]:.4f} from where the robot stands "
                        f"(tolerance {self.limits.start_command_tolerance})",
                    )
            excess = step - self._max_step
            j = int(excess.argmax())
            if float(excess[j]) > 0:
                raise self._refuse(
                    "max_step",
                    f"{self._joint(j)} would move {step[j]:.4f} in one control step (cap {self._max_step[j]})",
                )
            if self._speed_step is not None:
                a = np.clip(a, self._last - self._speed_step, self._last + self._speed_step)
        self._first = False
        self._last = a
        return a.astype(np.float32)
