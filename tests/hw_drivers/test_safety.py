"""The safety filter: every rule refuses what it must, stops the robot first, and passes what it may."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest
from numpy.typing import NDArray

from hw_drivers.errors import SafetyViolationError, StaleObservationError
from hw_drivers.safety import SafetyFilter, SafetyLimits
from pilworld.config.rig import RigConfig
from pilworld.types import RobotSpec

SIM = "configs/rig/sim_dual_ur5e.yaml"


class Clock:
    def __init__(self) -> None:
        self.now = 100.0

    def __call__(self) -> float:
        return self.now


@pytest.fixture
def spec() -> RobotSpec:
    base = RigConfig.load(SIM).robot_spec()
    return replace(base, max_joint_speed=tuple([np.pi] * 6 + [2.0]) * 2)


def _filter(spec: RobotSpec, **kw: float) -> tuple[SafetyFilter, list[int], Clock]:
    stops: list[int] = []
    clock = Clock()
    f = SafetyFilter(spec, SafetyLimits(**kw), clock=clock, on_violation=lambda: stops.append(1))
    return f, stops, clock


def _home(spec: RobotSpec) -> NDArray[np.float64]:
    mid = (spec.lower_array.astype(np.float64) + spec.upper_array.astype(np.float64)) / 2
    return np.asarray(mid, dtype=np.float64)


def test_a_command_near_the_robot_passes_and_is_slowed_to_the_speed_cap(spec: RobotSpec) -> None:
    f, stops, _ = _filter(spec)
    q = _home(spec)
    f.check_start(q, q)
    a = q.copy()
    a[0] += 0.2  # within the step cap (0.35) but faster than pi rad/s at 30 Hz (0.105 per step)
    out = f(a)
    assert out.dtype == np.float32
    assert out[0] == pytest.approx(q[0] + np.pi / 30, abs=1e-6)
    np.testing.assert_allclose(out[1:], q[1:], atol=1e-6)
    # A gripper may open or close in one command (capped by its own speed only).
    b = out.astype(np.float64)
    b[6] = 1.0 if q[6] < 0.5 else 0.0
    assert abs(float(f(b)[6]) - q[6]) == pytest.approx(2.0 / 30, abs=1e-6)
    assert stops == []


@pytest.mark.parametrize("bad", [np.nan, np.inf, -np.inf])
def test_non_finite_is_refused_and_stops(spec: RobotSpec, bad: float) -> None:
    f, stops, _ = _filter(spec)
    q = _home(spec)
    f.reset(q)
    a = q.copy()
    a[3] = bad
    with pytest.raises(SafetyViolationError, match=r"finite: .*left_wrist_1|finite") as e:
        f(a)
    assert e.value.check == "finite" and stops == [1]


def test_wrong_shape_is_refused(spec: RobotSpec) -> None:
    f, stops, _ = _filter(spec)
    with pytest.raises(SafetyViolationError, match="shape"):
        f(np.zeros(7))
    assert stops == [1]


def test_out_of_limit_is_refused_but_a_hair_over_is_clipped(spec: RobotSpec) -> None:
    f, stops, _ = _filter(spec, max_arm_step=10.0)
    q = spec.upper_array.astype(np.float64) - 0.01
    f.reset(q)
    a = q.copy()
    a[1] = spec.upper_array[1] + 0.03  # inside the 0.05 margin: clipped onto the limit
    assert float(f(a)[1]) == pytest.approx(spec.upper_array[1], abs=1e-6)
    a[1] = spec.upper_array[1] + 0.2
    with pytest.raises(SafetyViolationError, match="joint_limits") as e:
        f(a)
    assert spec.joint_names[1] in str(e.value) and stops == [1]


def test_an_oversized_step_is_refused(spec: RobotSpec) -> None:
    f, stops, _ = _filter(spec)
    q = _home(spec)
    f.reset(q)
    f(q)  # past the first command
    a = q.copy()
    a[8] += 0.5
    with pytest.raises(SafetyViolationError, match="max_step") as e:
        f(a)
    assert spec.joint_names[8] in str(e.value) and stops == [1]


def test_a_stale_observation_is_refused(spec: RobotSpec) -> None:
    f, stops, clock = _filter(spec, max_observation_age=0.5)
    f.check_observation(clock.now - 0.4)
    assert stops == []
    with pytest.raises(StaleObservationError, match=r"0\.700 s old"):
        f.check_observation(clock.now - 0.7)
    assert stops == [1]


def test_no_clock_no_staleness_rule(spec: RobotSpec) -> None:
    f = SafetyFilter(spec)
    f.check_observation(-1e9)  # the imagined branch has no robot clock


def test_start_pose_gate_robot_side(spec: RobotSpec) -> None:
    f, stops, _ = _filter(spec)
    q = _home(spec)
    away = q.copy()
    away[2] += 0.05
    with pytest.raises(SafetyViolationError, match="not at the start") as e:
        f.check_start(away, q)
    assert e.value.check == "start_pose" and spec.joint_names[2] in str(e.value) and stops == [1]


def test_start_pose_gate_command_side(spec: RobotSpec) -> None:
    f, stops, _ = _filter(spec)
    q = _home(spec)
    f.check_start(q, q)
    first = q.copy()
    first[7] += 0.3  # a chunk that begins elsewhere than where the robot stands
    with pytest.raises(SafetyViolationError, match="first command") as e:
        f(first)
    assert e.value.check == "start_command" and stops == [1]
    # The same jump later in the episode is only slowed (it is under the step cap).
    f.check_start(q, q)
    f(q)
    out = f(first)
    assert float(out[7]) == pytest.approx(q[7] + np.pi / 30, abs=1e-6)


def test_limits_are_validated() -> None:
    with pytest.raises(ValueError, match="max_arm_step"):
        SafetyLimits(max_arm_step=-1.0)
    with pytest.raises(ValueError, match="limit_margin"):
        SafetyLimits(limit_margin=float("nan"))
