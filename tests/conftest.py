"""Fixtures shared across test packages."""

from __future__ import annotations

from collections.abc import Callable, Iterator

import pytest

from simrig.files import SIM_RIG  # the one definition; the tests import it from here too


@pytest.fixture(scope="session")
def robots() -> Iterator[Callable[[str], object]]:
    """One connected simulated robot per task, shared by the session (connect costs ~0.2 s).

    Tests reset the robot they use before relying on its state.
    """
    from simrig.robot import SimRobot

    made: dict[str, SimRobot] = {}

    def get(task: str) -> SimRobot:
        if task not in made:
            made[task] = SimRobot(SIM_RIG, task)
            made[task].connect()
        return made[task]

    yield get
    for robot in made.values():
        robot.disconnect()


@pytest.fixture(autouse=True)
def _no_real_time_left_behind(request: pytest.FixtureRequest) -> Iterator[None]:
    """No test may leave the test process under a real-time scheduling policy.

    Found in a CI-style run: something made the pytest thread SCHED_FIFO 99, and every process it started
    after that inherited it. Two such CPU-bound children on two cores never yield to an equal-priority
    FIFO task, so the test process itself stopped running (a 600 s hang), and a fake rig's busy processes
    starved each other (watchdog stops). This names the test that did it and puts the policy back.
    """
    import os

    if not hasattr(os, "sched_getscheduler"):  # not Linux: no such policies to leak
        yield
        return
    before = os.sched_getscheduler(0)
    yield
    after = os.sched_getscheduler(0)
    if after != before:
        os.sched_setscheduler(0, before, os.sched_param(0))
        pytest.fail(f"{request.node.nodeid} left the test process under scheduling policy {after} (was {before})")
