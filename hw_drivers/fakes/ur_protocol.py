"""The wire side of the fake UR controller: ports, versions, RTDE message types and variable types, modes.

Kept apart from :mod:`hw_drivers.fakes.ur_controller` (the controller's behaviour) so that the tables
ur_rtde's decoder dictates (``src/robot_state.cpp``) can be read and checked on their own.
"""

from __future__ import annotations

import re
import struct

import numpy as np
from numpy.typing import NDArray

RTDE_PORT, DASHBOARD_PORT, SCRIPT_PORT = 30004, 29999, 30003
CONTROLLER_VERSION = (5, 11, 1, 108318)
POLYSCOPE_VERSION = "URSoftware 5.11.1.108318 (Mar 22 2021)"
TICK_S = 0.002  # the controller's 500 Hz cycle ("sync()" in URScript)

# RTDE message types
MSG_V, MSG_v, MSG_O, MSG_I, MSG_S, MSG_P, MSG_U = 86, 118, 79, 73, 83, 80, 85
# runtime_state, robot_mode, safety_mode values (ur_rtde's enums)
STOPPED, PLAYING = 1, 2
POWER_OFF, IDLE, RUNNING = 3, 5, 7
SAFETY = {  # name -> (safety_mode, safety_status_bits, dashboard word)
    "normal": (1, 1 << 0, "NORMAL"),
    "protective_stop": (3, (1 << 2) | (1 << 10), "PROTECTIVE_STOP"),
    "emergency_stop": (7, (1 << 6) | (1 << 7) | (1 << 10), "ROBOT_EMERGENCY_STOP"),
}
ROBOT_MODE_NAMES = {POWER_OFF: "POWER_OFF", IDLE: "IDLE", RUNNING: "RUNNING"}
STOP_CMDS = {15, 16, 33, 34}  # speedStop, servoStop, stopL, stopJ

FMT = {"VECTOR6D": "6d", "VECTOR3D": "3d", "DOUBLE": "d", "INT32": "i", "UINT32": "I", "UINT64": "Q"}
FMT.update({"VECTOR6INT32": "6i", "UINT8": "B", "BOOL": "?"})
_VEC6 = [
    "target_q",
    "target_qd",
    "target_qdd",
    "target_current",
    "target_moment",
    "actual_q",
    "actual_qd",
    "actual_qdd",
    "actual_current",
    "actual_moment",
    "joint_control_output",
    "actual_TCP_pose",
    "actual_TCP_speed",
    "actual_TCP_force",
    "target_TCP_pose",
    "target_TCP_speed",
    "joint_temperatures",
    "actual_joint_voltage",
    "ft_raw_wrench",
    "payload_inertia",
]
_SCALAR = [
    "timestamp",
    "actual_execution_time",
    "speed_scaling",
    "target_speed_fraction",
    "actual_momentum",
    "actual_main_voltage",
    "actual_robot_voltage",
    "actual_robot_current",
    "standard_analog_input0",
    "standard_analog_input1",
    "standard_analog_output0",
    "standard_analog_output1",
    "payload",
]
_OUT_TYPES = {n: "VECTOR6D" for n in _VEC6} | {n: "DOUBLE" for n in _SCALAR}
_OUT_TYPES |= {n: "VECTOR3D" for n in ("actual_tool_accelerometer", "payload_cog", "elbow_position")}
_OUT_TYPES |= {"robot_mode": "INT32", "safety_mode": "INT32", "joint_mode": "VECTOR6INT32"}
_OUT_TYPES |= {n: "UINT64" for n in ("actual_digital_input_bits", "actual_digital_output_bits")}
_OUT_TYPES |= {n: "UINT32" for n in ("runtime_state", "robot_status_bits", "safety_status_bits")}
_OUT_TYPES |= {n: "UINT32" for n in ("output_bit_registers0_to_31", "output_bit_registers32_to_63")}
_IN_TYPES = {"external_force_torque": "VECTOR6D", "speed_slider_mask": "UINT32", "speed_slider_fraction": "DOUBLE"}


def register_index(name: str, prefix: str) -> int | None:
    """``output_int_register_7`` -> 7 for prefix ``output_int_register_`` (registers 0 … 47), else None."""
    if name.startswith(prefix) and name[len(prefix) :].isdigit() and int(name[len(prefix) :]) < 48:
        return int(name[len(prefix) :])
    return None


def type_of(name: str, direction: str) -> str:
    for kind, rtde_type in (("int", "INT32"), ("double", "DOUBLE")):
        if register_index(name, f"{direction}_{kind}_register_") is not None:
            return rtde_type
    table = _OUT_TYPES if direction == "output" else _IN_TYPES
    if direction == "input" and name.startswith(("standard_", "configurable_", "tool_")):
        return "DOUBLE" if "analog_output_" in name and not name.endswith("type") else "UINT8"
    return table.get(name, "NOT_FOUND")


# A waypoint line ur_rtde's Path::toScriptCode injects into exec_move_path(): movej([q…],a=…,v=…,r=…)
_PATH_LINE = re.compile(r"^\s*(movej|movel)\((p?)\[([^\]]*)\],a=([^,]+),v=([^,]+),r=([^)]+)\)\s*$")
Waypoint = tuple[str, bool, NDArray[np.float64], float]  # move, is a pose, target, speed


def parse_path(script: str) -> list[Waypoint]:
    """The waypoints of an uploaded program's movej/movel lines; blend radius and acceleration are not used."""
    path: list[Waypoint] = []
    for line in script.splitlines():
        if (m := _PATH_LINE.match(line)) is not None:
            target = np.array([float(v) for v in m.group(3).split(",")])
            path.append((m.group(1), m.group(2) == "p", target, float(m.group(5))))
    return path


def frame(msg_type: int, payload: bytes = b"") -> bytes:
    return struct.pack(">HB", 3 + len(payload), msg_type) + payload
