"""The two branches behind one chunk-level interface: :class:`RobotEnv` (real) and :class:`ImaginedEnv`."""

from pilworld.envs.base import Env, EnvError
from pilworld.envs.imagined import HistoryMemory, ImaginedEnv
from pilworld.envs.robot import LimitFilter, RobotEnv

__all__ = ["Env", "EnvError", "HistoryMemory", "ImaginedEnv", "LimitFilter", "RobotEnv"]
