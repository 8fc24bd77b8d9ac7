"""Kinematics of the robot arms used by PiL-World (currently the Universal Robots family)."""

from pilworld.kinematics.dual_arm import ArmMount, DualArmKinematics
from pilworld.kinematics.fk import UrArm, fk, fk_flange, fk_frames, joint_transforms
from pilworld.kinematics.ik import IK_JOINT_WEIGHTS, IKError, ik_all, ik_nearest, ik_solve
from pilworld.kinematics.ur_dh import UR_DEFAULT_JOINT_LIMITS, UR_MODELS, DHParams, dh_params

__all__ = [
    "IK_JOINT_WEIGHTS",
    "UR_DEFAULT_JOINT_LIMITS",
    "UR_MODELS",
    "ArmMount",
    "DHParams",
    "DualArmKinematics",
    "IKError",
    "UrArm",
    "dh_params",
    "fk",
    "fk_flange",
    "fk_frames",
    "ik_all",
    "ik_nearest",
    "ik_solve",
    "joint_transforms",
]
