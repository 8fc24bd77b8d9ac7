"""The command ids of ur_rtde's ``rtde_control`` script (``RobotCommand::Type`` in ur_rtde's ``rtde.h``).

The client writes the id to ``input_int_register_0`` and the arguments to ``input_double_register_*`` /
``input_int_register_1…``; the script answers in ``output_int_register_0`` (1 ready, 2 done) and, for
queries, ``output_double_register_0…5`` / ``output_int_register_1``. The fake controller emulates the
ids in :data:`IMPLEMENTED`; every other id in :data:`NAMES` is listed in :data:`UNSUPPORTED` and stops the
program, as a URScript runtime error would, so the client sees a failed call (``False`` or "… function
did not succeed!") instead of a silent success.
"""

from __future__ import annotations

NAMES: dict[int, str] = {
    1: "moveJ",
    2: "moveJ_IK",
    3: "moveL",
    4: "moveL_FK",
    6: "forceMode",
    7: "forceModeStop",
    8: "zeroFtSensor",
    9: "speedJ",
    10: "speedL",
    11: "servoJ",
    12: "servoC",
    13: "setStandardDigitalOut",
    14: "setToolDigitalOut",
    15: "speedStop",
    16: "servoStop",
    17: "setPayload",
    18: "teachMode",
    19: "endTeachMode",
    20: "forceModeSetDamping",
    21: "forceModeSetGainScaling",
    22: "setSpeedSlider",
    23: "setAnalogOutput",
    24: "servoL",
    25: "toolContact",
    26: "getStepTime",
    27: "getActualJointPositionsHistory",
    28: "getTargetWaypoint",
    29: "setTcp",
    30: "getInverseKinematics(x, qnear, …)",
    31: "triggerProtectiveStop",
    33: "stopL",
    34: "stopJ",
    35: "setWatchdog",
    36: "isPoseWithinSafetyLimits",
    37: "isJointsWithinSafetyLimits",
    38: "getJointTorques",
    39: "poseTrans",
    40: "getTCPOffset",
    41: "jogStart",
    42: "jogStop",
    43: "getForwardKinematics()",
    44: "getForwardKinematics(q, tcp)",
    45: "moveJ/moveL(path)",
    46: "getInverseKinematics(x)",
    47: "isSteady",
    48: "setConfigurableDigitalOut",
    49: "setInputIntRegister",
    50: "setInputDoubleRegister",
    51: "moveUntilContact",
    52: "freedriveMode",
    53: "endFreedriveMode",
    54: "getFreedriveStatus",
    55: "setExternalForceTorque",
    56: "ftRtdeInputEnable",
    57: "enableExternalFtSensor",
    58: "getActualToolFlangePose",
    59: "setGravity",
    60: "getInverseKinematicsHasSolution(x)",
    61: "getInverseKinematicsHasSolution(x, qnear, …)",
    62: "startContactDetection",
    63: "stopContactDetection",
    64: "readContactDetection",
    65: "setTargetPayload",
    66: "directTorque",
    67: "getMassMatrix",
    68: "getCoriolisAndCentrifugalTorques",
    69: "getTargetJointAccelerations",
    70: "getJacobian",
    71: "getJacobianTimeDerivative",
    255: "stopScript",
}

# The script's main loop processes these and signals "ready" again without "done" (rtde_control.script 1.6.5).
REALTIME = frozenset({6, 9, 10, 11, 24, 25, 26, 27, 38, 58, 66, 67, 68, 69, 70, 71})

IMPLEMENTED = frozenset(
    {1, 2, 3, 4, 9, 10, 11, 15, 16, 24, 29, 30, 31, 33, 34, 35, 40, 43, 44, 45, 46, 47, 58, 60, 61, 255}
)
UNSUPPORTED = frozenset(NAMES) - IMPLEMENTED


def describe(cmd: int) -> str:
    """``"forceMode (6)"`` for a known id, ``"unknown command 77"`` otherwise."""
    return f"{NAMES[cmd]} ({cmd})" if cmd in NAMES else f"unknown command {cmd}"
