"""The rig config: two arms in a common rig frame, their grippers, the cameras, image size and rate.

``configs/rig/sim_dual_ur5e.yaml`` describes the simulated rig and ``configs/rig/real_dual_ur5e.yaml``
is the template for a real one. The head camera comes either from a calibration file (``file:``, a
``pilworld.camera_model/v1`` YAML written by ``pilworld calibrate``) or, for the simulator, from a
look-at pose and a vertical field of view.

Images are brought to ``image_size`` the way openpi does (resize keeping the aspect ratio, then pad
symmetrically with black), and the head camera model follows the same geometry, so projected points
land on the pixels the policy and the world model see.
"""

from __future__ import annotations

import dataclasses
import math
from functools import cached_property
from pathlib import Path
from typing import Any, Literal

import numpy as np
from numpy.typing import NDArray
from pydantic import Field, ValidationInfo, field_validator, model_validator

from calib.camera_model import CameraModel
from pilworld.config.hardware import HardwareConfig
from pilworld.config.loader import StrictModel, load_yaml_model
from pilworld.geometry import invert_transform, pose_to_matrix
from pilworld.kinematics.dual_arm import ArmMount, DualArmKinematics
from pilworld.kinematics.ur_dh import dh_params
from pilworld.types import ARM_SIDES, HEAD_VIEW, RobotSpec, dual_arm_joint_names

Vec3 = tuple[float, float, float]


class Pose(StrictModel):
    """A rigid pose: translation in metres, rotation as roll-pitch-yaw in radians (R = Rz·Ry·Rx)."""

    xyz: Vec3 = (0.0, 0.0, 0.0)
    rpy: Vec3 = (0.0, 0.0, 0.0)

    def matrix(self) -> NDArray[np.float64]:
        return pose_to_matrix(np.array(self.xyz), np.array(self.rpy))


def _resolve_file(value: str | None, info: ValidationInfo) -> str | None:
    """A camera file path, relative paths resolved against the rig file's folder; it must exist."""
    if value is None:
        return None
    path = Path(value).expanduser()
    base = (info.context or {}).get("base_dir")
    if not path.is_absolute() and base is not None:
        path = Path(base) / path
    if not path.is_file():
        raise ValueError(f"camera file not found: {path}")
    return str(path)


class ImageSize(StrictModel):
    width: int = Field(gt=0, le=8192)
    height: int = Field(gt=0, le=8192)


class GripperConfig(StrictModel):
    """A parallel-jaw gripper; the grip value 0 = closed … 1 = open maps linearly to the finger gap."""

    kind: Literal["parallel_jaw"] = "parallel_jaw"
    max_opening_m: float = Field(default=0.085, gt=0, le=0.5)  # finger gap at grip = 1


class ArmConfig(StrictModel):
    model: str  # a UR model with a published DH table: ur3e, ur5e, ur10e, ur16e, ur20, ur30, ur3, ur5, ur10
    base_pose: Pose  # the arm's base frame in the rig frame
    tcp: Pose = Pose(xyz=(0.0, 0.0, 0.15))  # flange → tool centre point (between the fingertips)
    gripper: GripperConfig = GripperConfig()

    @field_validator("model")
    @classmethod
    def _known_model(cls, value: str) -> str:
        dh_params(value)  # raises ValueError listing the valid names
        return value


class Arms(StrictModel):
    left: ArmConfig
    right: ArmConfig


class LookAt(StrictModel):
    """An undistorted pinhole camera looking from ``eye`` at ``target`` (rig frame, metres)."""

    eye: Vec3
    target: Vec3
    up: Vec3 = (0.0, 0.0, 1.0)
    fovy_deg: float = Field(gt=1.0, lt=170.0)


class HeadCameraConfig(StrictModel):
    """Exactly one of ``file`` (a calibration result) or ``look_at`` (a designed camera)."""

    file: str | None = None  # pilworld.camera_model/v1 YAML; relative paths resolve against the rig file
    look_at: LookAt | None = None

    @model_validator(mode="after")
    def _exactly_one(self) -> HeadCameraConfig:
        if (self.file is None) == (self.look_at is None):
            raise ValueError("give exactly one of 'file' (calibrated camera) or 'look_at' (designed camera)")
        return self

    @field_validator("file")
    @classmethod
    def _resolve(cls, value: str | None, info: ValidationInfo) -> str | None:
        return _resolve_file(value, info)


class WristCameraConfig(StrictModel):
    """A camera fixed to one gripper: its pose relative to that arm's TCP (OpenCV axes: z forward).

    ``pose_in_tcp`` and ``fovy_deg`` are the designed mount (the simulator places the camera there, and
    eye-in-hand calibration plans its poses from it). ``file``, written by ``pilworld calibrate handeye
    --camera NAME``, is the calibrated camera: a ``pilworld.camera_model/v1`` YAML whose ``T_cam_base``
    maps points of this arm's **TCP frame** into the camera frame (``T_cam_tcp``), with the measured
    intrinsics; when given, it replaces the designed mount and field of view everywhere the rig's
    geometry is used (control video, reprojection prior, checks).
    """

    arm: Literal["left", "right"]
    pose_in_tcp: Pose
    fovy_deg: float = Field(default=70.0, gt=1.0, lt=170.0)
    file: str | None = None  # calibrated wrist camera (T_cam_base = T_cam_tcp); relative to the rig file

    @field_validator("file")
    @classmethod
    def _resolve(cls, value: str | None, info: ValidationInfo) -> str | None:
        return _resolve_file(value, info)


class RobotModelConfig(StrictModel):
    """The user's own MJCF robot model, rendered by the control video instead of the generated one.

    The file holds the robot only (no table), in the rig frame. ``arm_joints`` name the six hinge
    joints of each arm in the 14-d order; ``finger_joints`` the joints a grip value drives (each set to
    ``lower + grip · (upper − lower)`` of its range, so grip 1 = open must be the upper end). Geoms of
    bodies at or below a finger joint are that arm's fingers; the other geoms below the arm's first joint's
    parent body are the arm. The rig's DH kinematics (``arms``) must describe the same arms: the TCP and
    the wrist cameras are placed by it.
    """

    mjcf: str  # path of the MJCF file; relative paths resolve against the rig file
    arm_joints: dict[Literal["left", "right"], list[str]]
    finger_joints: dict[Literal["left", "right"], list[str]] = Field(default_factory=dict)

    @field_validator("mjcf")
    @classmethod
    def _resolve_mjcf(cls, value: str, info: ValidationInfo) -> str:
        path = Path(value).expanduser()
        base = (info.context or {}).get("base_dir")
        if not path.is_absolute() and base is not None:
            path = Path(base) / path
        if not path.is_file():
            raise ValueError(f"robot model file not found: {path}")
        return str(path)

    @field_validator("arm_joints")
    @classmethod
    def _six_joints(cls, value: dict[str, list[str]]) -> dict[str, list[str]]:
        for side in ARM_SIDES:
            if side not in value:
                raise ValueError(f"arm_joints: missing {side!r} (need six joint names per arm)")
            if len(value[side]) != 6:
                raise ValueError(f"arm_joints.{side}: expected six joint names, got {len(value[side])}")
        return value


class RigConfig(StrictModel):
    """A dual-arm rig: the single source of its geometry for the simulator, Γ and calibration checks."""

    name: str = Field(min_length=1)
    control_rate_hz: float = Field(default=30.0, gt=0, le=1000)  # policy/control steps per second
    servo_rate_hz: float = Field(default=500.0, gt=0)  # arm controller interpolation rate underneath
    # Control steps the measured joints trail the commanded ones (servo tracking): Γ⁺'s render and prior place
    # the arm there (pilworld/control_video/lag.py; `pilworld bench reprojection` estimates it from rounds).
    control_lag_steps: float = Field(default=0.0, ge=0.0, le=45.0)
    image_size: ImageSize = ImageSize(width=128, height=128)  # every camera, as the policy sees it
    arms: Arms
    head_camera: HeadCameraConfig
    wrist_cameras: dict[str, WristCameraConfig] = Field(default_factory=dict)
    hardware: HardwareConfig | None = None  # drivers of a real rig (or its protocol fakes); None: simulated
    robot_model: RobotModelConfig | None = None  # own MJCF for the control video's render; None: generated

    @model_validator(mode="after")
    def _hardware_cameras(self) -> RigConfig:
        if self.hardware is not None:
            missing = [c for c in self.cameras if c not in self.hardware.cameras]
            extra = [c for c in self.hardware.cameras if c not in self.cameras]
            if missing or extra:
                raise ValueError(
                    f"hardware.cameras must name the rig's cameras {list(self.cameras)}"
                    + (f"; missing {missing}" if missing else "")
                    + (f"; unknown {extra}" if extra else "")
                )
            fake = self.hardware.fake
            for name, size in (fake.stream_sizes if fake is not None else {}).items():
                if name not in self.cameras:
                    raise ValueError(
                        f"hardware.fake.stream_sizes: unknown camera {name!r} (the rig's: {list(self.cameras)})"
                    )
                w, h = self.image_size.width, self.image_size.height
                # Same field of view and square pixels: only the rig image's aspect keeps every pixel's ray.
                if size.width * h != size.height * w:
                    raise ValueError(
                        f"hardware.fake.stream_sizes.{name}: {size.width}x{size.height} has another aspect than the "
                        f"rig's image_size {w}x{h}"
                    )
        return self

    @field_validator("wrist_cameras")
    @classmethod
    def _wrist_names(cls, value: dict[str, WristCameraConfig]) -> dict[str, WristCameraConfig]:
        if HEAD_VIEW in value:
            raise ValueError(f"{HEAD_VIEW!r} is the head camera; wrist cameras need other names")
        return value

    @property
    def cameras(self) -> tuple[str, ...]:
        """Camera keys, head first (``cam_high``, then the wrist cameras in file order)."""
        return (HEAD_VIEW, *self.wrist_cameras)

    @cached_property
    def kinematics(self) -> DualArmKinematics:
        mounts = {
            side: ArmMount(dh=dh_params(arm.model), T_rig_base=arm.base_pose.matrix(), T_flange_tcp=arm.tcp.matrix())
            for side, arm in (("left", self.arms.left), ("right", self.arms.right))
        }
        return DualArmKinematics(left=mounts["left"], right=mounts["right"])

    @cached_property
    def head_camera_model(self) -> CameraModel:
        """The head camera at ``image_size`` (a calibrated camera is letterboxed like the images)."""
        width, height = self.image_size.width, self.image_size.height
        if self.head_camera.look_at is not None:
            la = self.head_camera.look_at
            return CameraModel.look_at(
                eye=np.array(la.eye),
                target=np.array(la.target),
                up=np.array(la.up),
                fovy_deg=la.fovy_deg,
                width=width,
                height=height,
                name=HEAD_VIEW,
            )
        assert self.head_camera.file is not None  # guaranteed by HeadCameraConfig._exactly_one
        return letterbox(CameraModel.from_yaml(self.head_camera.file), width, height)

    def wrist_camera_model(self, name: str) -> CameraModel:
        """Wrist camera ``name`` at ``image_size``; its ``T_cam_base`` is ``T_cam_tcp`` (TCP frame → camera).

        From the calibration ``file`` when the rig has one (letterboxed like the images), else the
        designed mount: an undistorted pinhole of ``fovy_deg`` (square pixels, centred principal
        point, MuJoCo's convention) at ``pose_in_tcp``.
        """
        if name not in self.wrist_cameras:
            raise ValueError(f"wrist camera {name!r}: rig {self.name!r} has wrist cameras {list(self.wrist_cameras)}")
        cam = self.wrist_cameras[name]
        width, height = self.image_size.width, self.image_size.height
        if cam.file is not None:
            return dataclasses.replace(letterbox(CameraModel.from_yaml(cam.file), width, height), name=name)
        f = height / (2.0 * math.tan(math.radians(cam.fovy_deg) / 2.0))
        K = np.array([[f, 0.0, (width - 1) / 2.0], [0.0, f, (height - 1) / 2.0], [0.0, 0.0, 1.0]])
        T_cam_tcp = invert_transform(cam.pose_in_tcp.matrix())
        return CameraModel(K=K, dist=np.zeros(0), T_cam_base=T_cam_tcp, width=width, height=height, name=name)

    def robot_spec(self) -> RobotSpec:
        """Joint names and limits of the 14-d vector, cameras, rate and image size."""
        lower: list[float] = []
        upper: list[float] = []
        for arm in (self.arms.left, self.arms.right):
            dh = dh_params(arm.model)
            lower += [float(v) for v in dh.lower_limits] + [0.0]
            upper += [float(v) for v in dh.upper_limits] + [1.0]
        return RobotSpec(
            joint_names=dual_arm_joint_names(ARM_SIDES),
            lower=tuple(lower),
            upper=tuple(upper),
            cameras=self.cameras,
            control_rate_hz=self.control_rate_hz,
            image_size=(self.image_size.width, self.image_size.height),
        )

    @classmethod
    def load(cls, path: str | Path) -> RigConfig:
        """Load and validate a rig YAML; errors name the file and the field."""
        return load_yaml_model(cls, path)


def letterbox(camera: CameraModel, width: int, height: int) -> CameraModel:
    """The camera as seen after openpi's ``resize_with_pad`` to (width, height).

    openpi scales by ``ratio = max(w / width, h / height)`` to ``(int(w / ratio), int(h / ratio))`` and
    pads the rest symmetrically (left/top get ``pad // 2``), so the principal point shifts by the pad.
    """
    if (camera.width, camera.height) == (width, height):
        return camera
    ratio = max(camera.width / width, camera.height / height)
    new_w, new_h = int(camera.width / ratio), int(camera.height / ratio)
    scaled = camera.resized(new_w, new_h)
    K = scaled.K.copy()
    K[0, 2] += (width - new_w) // 2
    K[1, 2] += (height - new_h) // 2
    return dataclasses.replace(scaled, K=K, width=width, height=height)


def rig_summary(rig: RigConfig) -> dict[str, Any]:
    """A JSON-friendly summary (used by the CLI and bench output)."""
    cam = rig.head_camera_model
    return {
        "rig": rig.name,
        "arms": {side: getattr(rig.arms, side).model for side in ARM_SIDES},
        "image_size": [rig.image_size.width, rig.image_size.height],
        "control_rate_hz": rig.control_rate_hz,
        "head_camera": {
            "fx": float(cam.K[0, 0]),
            "fy": float(cam.K[1, 1]),
            "dist_coeffs": int(cam.dist.size),
        },
    }
