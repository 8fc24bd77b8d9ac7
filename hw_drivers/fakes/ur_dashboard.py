"""The fake UR controller's dashboard answers (port 29999) that only read its state.

The commands that change the controller (stop, play, pause, power, brakes, unlock) stay with
:class:`~hw_drivers.fakes.ur_controller.FakeURController`; everything else a client asks is answered
here, with the strings ``ur_rtde``'s ``DashboardClient`` compares against.
"""

from __future__ import annotations

from dataclasses import dataclass

from hw_drivers.fakes.ur_protocol import POLYSCOPE_VERSION, ROBOT_MODE_NAMES, SAFETY


@dataclass(frozen=True)
class DashboardState:
    """What the read-only answers report."""

    robot_mode: int
    safety: str  # a key of SAFETY
    playing: bool
    program: str  # the loaded program's name, or "<unnamed>"


def status_reply(line: str, state: DashboardState) -> str:
    """The answer to a dashboard ``line`` that does not change the controller."""
    cmd = line.lower()
    program = state.program
    answers = {
        "robotmode": f"Robotmode: {ROBOT_MODE_NAMES[state.robot_mode]}",
        "safetystatus": f"Safetystatus: {SAFETY[state.safety][2]}",
        "safetymode": f"Safetymode: {SAFETY[state.safety][2]}",
        "programstate": f"{'PLAYING' if state.playing else 'STOPPED'} {program}",
        "running": f"Program running: {str(state.playing).lower()}",
        "polyscopeversion": POLYSCOPE_VERSION,
        "get serial number": "20185500000",
        "is in remote control": "true",
        "get robot model": "UR5",
        "get loaded program": f"Loaded program: {program}",
        "isprogramsaved": f"true {program}",
        "close popup": "closing popup",
        "close safety popup": "closing safety popup",
        "restart safety": "Restarting safety",
        "quit": "Disconnected",
        "shutdown": "Shutting down",
    }
    if cmd in answers:
        return answers[cmd]
    if cmd.startswith("load "):
        return f"Loading program: {line[5:]}"
    if cmd.startswith(("popup ", "addtolog ", "setuserrole ")):
        return "ok"
    return f"could not understand: '{line}'"
