"""The two branches behind one chunk-level interface: :class:`RobotEnv` (real) and :class:`ImaginedEnv`."""

from hw_drivers.safety import SafetyFilter, SafetyLimits
from pilworld.envs.base import Env, EnvError
from pilworld.envs.imagined import HistoryMemory, ImaginedEnv
from pilworld.envs.robot import RobotEnv, robot_safety_filter

__all__ = [
    "Env",
    "EnvError",
    "HistoryMemory",
    "ImaginedEnv",
    "RobotEnv",
    "SafetyFilter",
    "SafetyLimits",
    "robot_safety_filter",
]
