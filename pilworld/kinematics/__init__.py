"""Kinematics of the robot arms used by PiL-World (currently the Universal Robots family)."""

from pilworld.kinematics.dual_arm import ArmMount, DualArmKinematics
from pilworld.kinematics.fk import UrArm, fk, fk_flange, fk_frames, joint_transforms
from pilworld.kinematics.ur_dh import UR_DEFAULT_JOINT_LIMITS, UR_MODELS, DHParams, dh_params

__all__ = [
    "UR_DEFAULT_JOINT_LIMITS",
    "UR_MODELS",
    "ArmMount",
    "DHParams",
    "DualArmKinematics",
    "UrArm",
    "dh_params",
    "fk",
    "fk_flange",
    "fk_frames",
    "joint_transforms",
]
