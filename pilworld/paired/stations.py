"""Where the real branch runs: the simulated rig, or a hardware rig (real, or its protocol fakes).

A station brings the robot to a subtask's start and says how the real branch ended:

* :class:`SimStation` — ``SimRobot.reset`` lays out the scene and records the H_h history frames
  during a lead-in; the simulator's privileged checker judges the end (``sim_checker``).
* :class:`HardwareStation` — the operator is asked to set up the scene (on the fake rig the simulated
  scene is laid out first, as a person would); the arms move to the start pose at a capped speed;
  H_h history frames and the start observation are captured from the cameras while the robot holds
  still; at the end the operator marks success or failure (a ``human`` judge, ``operator``) or leaves
  it to the annotation app. On the fake rig the simulator's checker judges too. A checkpoint whose
  server's metadata names a ``reset_pose`` starts from that pose instead (``reset_poses``).

Without a terminal the console operator cannot answer: the station refuses to open
(:class:`~pilworld.paired.operator.OperatorUnavailableError`) before anything moves. An
:class:`~pilworld.paired.operator.UnattendedOperator` runs the fake rig with nobody there and is refused
on real hardware.
"""

from __future__ import annotations

import dataclasses
import time
from collections.abc import Mapping, Sequence
from pathlib import Path
from types import TracebackType
from typing import Any, Protocol

import numpy as np

from hw_drivers.robot import Robot
from pilworld.config.rig import RigConfig
from pilworld.data.outcomes import Outcome
from pilworld.paired.operator import OPERATOR_JUDGE, ConsoleOperator, Operator, UnattendedOperator
from pilworld.types import ChunkSpec, Observation, Start, Subtask
from simrig.tasks import Task, load_task

SIM_JUDGE = "sim_checker"


def _task_map(tasks: str | Task | Sequence[str | Task] | Mapping[str, Task] | None) -> dict[str, Task]:
    """Tasks by name (a run's tasks are keyed by their names; see pilworld.collection.tasks)."""
    if tasks is None:
        return {}
    if isinstance(tasks, Mapping):
        return dict(tasks)
    items = [tasks] if isinstance(tasks, (str, Task)) else list(tasks)
    loaded = [load_task(t) for t in items]
    return {t.name: t for t in loaded}


def _task_of(tasks: Mapping[str, Task], subtask: Subtask) -> Task:
    """The task a subtask belongs to: one of the run's, else the packaged task of that name."""
    return tasks.get(subtask.task) or load_task(subtask.task)


class Station(Protocol):
    @property
    def robot(self) -> Robot: ...

    @property
    def pace(self) -> bool:
        """Whether the real branch must keep to the control clock (hardware) or may run ahead (simulation)."""
        ...

    @property
    def order(self) -> tuple[str, ...]:
        """The order the branches of a pair run in."""
        ...

    @property
    def shared_starts(self) -> bool:
        """Whether a subtask's start is the same scene for every checkpoint (stored once) or set up anew per pair."""
        ...

    def start(self, subtask: Subtask, checkpoint: str, spec: ChunkSpec) -> Start: ...

    def verdicts(self, subtask: Subtask, checkpoint: str, episode_index: int, num_frames: int) -> list[Outcome]: ...

    def __enter__(self) -> Station: ...

    def __exit__(
        self, exc_type: type[BaseException] | None, exc: BaseException | None, tb: TracebackType | None
    ) -> None: ...


class SimStation:
    """The simulated rig, in process."""

    pace = False  # physics advances with each command; nothing is gained by waiting for the wall clock
    order = ("imagined", "real")  # the simulated clock stands still while the world model runs
    shared_starts = True  # a layout seed lays out the same scene, bit for bit, whichever checkpoint runs

    def __init__(
        self,
        rig_path: str | Path | RigConfig,
        task: str | Task | Sequence[str | Task] | Mapping[str, Task],
        *,
        appearance: str = "flat",
    ) -> None:
        from simrig.robot import SimRobot

        self.tasks = _task_map(task)
        if not self.tasks:
            raise ValueError("task: a simulated station needs a task")
        self._robot = SimRobot(rig_path, next(iter(self.tasks.values())), appearance=appearance)

    @property
    def robot(self) -> Robot:
        return self._robot

    def start(self, subtask: Subtask, checkpoint: str, spec: ChunkSpec) -> Start:
        start = self._robot.reset(
            seed=subtask.seed,
            subtask=subtask.index,
            task=_task_of(self.tasks, subtask),
            history=spec.history,
            stride=spec.stride,
        )
        # The subtask as planned: its instruction may be the run's (--instruction) rather than the task file's.
        return dataclasses.replace(start, subtask=subtask)

    def verdicts(self, subtask: Subtask, checkpoint: str, episode_index: int, num_frames: int) -> list[Outcome]:
        check = self._robot.check_subtask(subtask.index)
        return [Outcome(episode_index, SIM_JUDGE, "sim_state", check.success, num_frames)]

    def __enter__(self) -> SimStation:
        self._robot.connect()
        return self

    def __exit__(self, *exc: object) -> None:
        self._robot.disconnect()


class HardwareStation:
    """A rig with a ``hardware:`` section: real devices, or (``hardware.fake``) the protocol fakes."""

    pace = True
    # Real branch first: its first chunk is computed from the start observation, which must be fresh
    # (the safety filter refuses stale ones); the imagined branch has no clock and runs after.
    order = ("real", "imagined")
    shared_starts = False  # the operator sets each pair's scene up anew

    def __init__(
        self,
        rig_path: str | Path,
        operator: Operator | None = None,
        *,
        seed: int = 0,
        settle_s: float = 0.5,
        tasks: str | Task | Sequence[str | Task] | Mapping[str, Task] | None = None,
        rig: RigConfig | None = None,
    ) -> None:
        self.rig_path = str(rig_path)  # the fakes' process loads the file itself
        # The run's tasks by name (a subtask of another task is looked up among the packaged ones).
        self.tasks = _task_map(tasks)
        self.rig = rig if rig is not None else RigConfig.load(rig_path)
        if self.rig.hardware is None:
            raise ValueError(f"rig {self.rig.name!r} has no 'hardware:' section; use SimStation for a simulated rig")
        self.hw = self.rig.hardware
        self.operator = operator or ConsoleOperator()
        if isinstance(self.operator, UnattendedOperator) and self.hw.fake is None:
            raise ValueError(
                f"--unattended: rig {self.rig.name!r} drives real hardware; an unattended run is only for the "
                "fake rig (a 'hardware.fake' section), where the simulator lays out each scene and judges it"
            )
        check = getattr(self.operator, "check_available", None)
        if callable(check):  # before the fakes start or a device connects: nothing has moved yet
            check(self.rig.name)
        # Per checkpoint: the pose its server's metadata asks to start from (pilworld.paired.policy_metadata).
        self.reset_poses: dict[str, np.ndarray[Any, np.dtype[np.float64]]] = {}
        self.fake: Any = None
        self._robot: Any = None
        self._seed = seed
        self.settle_s = settle_s

    @property
    def robot(self) -> Robot:
        if self._robot is None:
            raise RuntimeError("hardware station: not started (use it as a context manager)")
        robot: Robot = self._robot
        return robot

    def __enter__(self) -> HardwareStation:
        from hw_drivers.factory import build_robot

        endpoints = None
        try:
            if self.hw.fake is not None:
                from hw_drivers.fakes.rig import FakeRig

                self.fake = FakeRig(self.rig_path, seed=self._seed)
                endpoints = self.fake.start()
            self._robot = build_robot(self.rig, endpoints)
            self._robot.connect()
        except BaseException:
            self.__exit__(None, None, None)
            raise
        return self

    def __exit__(self, *exc: object) -> None:
        try:
            if self._robot is not None:
                self._robot.disconnect()
        finally:
            self._robot = None
            if self.fake is not None:
                self.fake.stop()
                self.fake = None

    def start_pose(self) -> np.ndarray[Any, np.dtype[np.float64]]:
        """The configured start pose, or (none configured) wherever the robot stands now."""
        if self.hw.start_pose is not None:
            return np.asarray(self.hw.start_pose, dtype=np.float64)
        return np.asarray(self._robot.state(), dtype=np.float64)

    def start(self, subtask: Subtask, checkpoint: str, spec: ChunkSpec) -> Start:
        task = _task_of(self.tasks, subtask)
        if self.fake is not None and task.simulated:  # the simulated scene stands in for the person setting it up
            from pilworld.collection.tasks import task_ref

            self.fake.reset(task_ref(task), subtask.seed, subtask.index)
        self.operator.set_up(subtask, checkpoint, setup=task.subtask(subtask.index).operator_setup)
        pose = self.reset_poses.get(checkpoint)
        self._robot.move_to(self.start_pose() if pose is None else pose, speed=self.hw.start_speed)
        # History: H_h frames at the policy's frame stride while the robot holds still at the start.
        period = spec.stride / self.rig.control_rate_hz
        frames: list[Observation] = []
        for _ in range(spec.history):
            frames.append(self._robot.observe())
            time.sleep(period)
        return Start(subtask=subtask, observation=self._robot.observe(), history=tuple(frames))

    def verdicts(self, subtask: Subtask, checkpoint: str, episode_index: int, num_frames: int) -> list[Outcome]:
        # No new commands: the arms hold their last target while the person looks. Let that last
        # command finish (a gripper still letting go at the final step) before judging; stopping the
        # gripper where it is would leave it on the object.
        time.sleep(self.settle_s)
        out: list[Outcome] = []
        task = _task_of(self.tasks, subtask)
        if self.fake is not None and task.simulated:  # a hardware-only task: the fake's scene is not this task's
            check = self.fake.check()
            out.append(Outcome(episode_index, SIM_JUDGE, "sim_state", bool(check["success"]), num_frames))
        verdict = self.operator.judge(subtask, checkpoint, success=task.subtask(subtask.index).operator_success)
        if verdict is not None:
            out.append(Outcome(episode_index, OPERATOR_JUDGE, "human", verdict, num_frames))
        return out


def open_station(
    rig_path: str | Path,
    task: str | Task | Sequence[str | Task] | Mapping[str, Task],
    operator: Operator | None = None,
    *,
    appearance: str = "flat",
    rig: RigConfig | None = None,
) -> SimStation | HardwareStation:
    """The station for ``rig_path``: hardware (or its fakes) when the file has a ``hardware:`` section.

    ``task`` is the run's task or tasks (names, files or loaded tasks); on a hardware rig a task file
    without objects is enough: the operator lays out each subtask and judges it. ``rig``: the rig file
    already loaded (a run loads it once)."""
    rig = rig if rig is not None else RigConfig.load(rig_path)
    if rig.hardware is not None:
        if appearance != "flat":
            raise ValueError(
                f"appearance: rig {rig.name!r} is a hardware rig; its scene is what stands on the table "
                f"(--appearance {appearance} is for the simulated rig)"
            )
        return HardwareStation(rig_path, operator, tasks=task, rig=rig)
    return SimStation(rig, task, appearance=appearance)
