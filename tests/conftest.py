"""Fixtures shared across test packages."""

from __future__ import annotations

from collections.abc import Callable, Iterator
from pathlib import Path

import pytest

SIM_RIG = Path(__file__).resolve().parents[1] / "configs" / "rig" / "sim_dual_ur5e.yaml"


@pytest.fixture(scope="session")
def robots() -> Iterator[Callable[[str], object]]:
    """One connected simulated robot per task, shared by the session (connect costs ~0.2 s).

    Tests reset the robot they use before relying on its state.
    """
    from hw_drivers.sim.robot import SimRobot

    made: dict[str, SimRobot] = {}

    def get(task: str) -> SimRobot:
        if task not in made:
            made[task] = SimRobot(SIM_RIG, task)
            made[task].connect()
        return made[task]

    yield get
    for robot in made.values():
        robot.disconnect()
