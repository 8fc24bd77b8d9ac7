"""Fixtures shared across test packages."""

from __future__ import annotations

from collections.abc import Callable, Iterator
from pathlib import Path

import pytest

from simrig.files import SIM_RIG  # the one definition; the tests import it from here too

ROOT = Path(__file__).resolve().parents[1]

# Tests that run the rig in real time (fake UR controllers, grippers and cameras on the wall clock, the drivers'
# servo loops) or on the fake rig's fixed loopback addresses (127.0.0.1/.2, the UR ports): a test beside them takes
# the CPU their timing needs, or their ports. Marked ``serial``: scripts/test runs them alone, then the rest in
# parallel (pytest-xdist). The browser test under load makes its own load and is here for the same reason.
SERIAL = (
    "tests/hw_drivers/",
    "tests/pilworld/calibration/test_rig_motion.py",
    "tests/pilworld/cli/test_calibrate_live_cli.py",
    "tests/pilworld/cli/test_calibrate_rig_cli.py",
    "tests/pilworld/judges/learned/test_real_rig_workflow.py",
    "tests/pilworld/paired/test_hardware_resume.py",
    "tests/pilworld/paired/test_operator_unattended.py",
    "tests/pilworld/paired/test_reset_pose.py",
    "tests/pilworld/paired/test_task_files.py",
    "tests/pilworld/report/test_browser_under_load.py",
)


def pytest_itemcollected(item: pytest.Item) -> None:
    """``serial`` by path, as each test is collected (before ``-m`` deselects by marker)."""
    path = Path(str(item.fspath)).resolve()
    rel = path.relative_to(ROOT).as_posix() if path.is_relative_to(ROOT) else path.as_posix()
    if rel.startswith(SERIAL):
        item.add_marker(pytest.mark.serial)


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
