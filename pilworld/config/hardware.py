"""The ``hardware:`` section of a rig file: which driver talks to each part, and where.

A rig file without it is the simulated rig. With it, ``pilworld robot check`` and ``pilworld paired
run`` build a :class:`hw_drivers.dual_arm.DualArmRobot` from these entries. ``fake:`` starts the
protocol-level fakes backed by the simulated rig (``configs/rig/fake_dual_ur5e.yaml``) and fills in
their addresses: serial ports written ``auto`` become the fakes' pseudo-terminals, camera sources
``auto`` their MJPEG streams.
"""

from __future__ import annotations

import ipaddress
from typing import Annotated, Literal

from pydantic import Field, field_validator, model_validator

from pilworld.config.loader import StrictModel

AUTO = "auto"  # filled in by the fake rig


class URArmDriverConfig(StrictModel):
    """A UR arm over RTDE (``ur_rtde``); the controller's ports are fixed (30004, 29999, 30003)."""

    driver: Literal["ur_rtde"] = "ur_rtde"
    host: str = Field(min_length=1)  # the controller's IP address or host name
    servo_rate_hz: float = Field(default=500.0, gt=0, le=1000)  # servoJ loop (the e-Series runs at 500 Hz)
    lookahead_time: float = Field(default=0.1, ge=0.03, le=0.2)  # servoJ smoothing [s] (UR's range)
    gain: float = Field(default=300.0, ge=100, le=2000)  # servoJ proportional gain (UR's range)
    connect_timeout: float = Field(default=10.0, gt=0)
    retries: int = Field(default=2, ge=0, le=10)
    # The servo loop's interpolation toward each target never exceeds this joint speed [rad/s]
    # (a UR e-Series joint's maximum is π; the safety filter already slows commands to it).
    max_joint_speed: float = Field(default=3.141592653589793, gt=0, le=3.2)
    # RTDE silence [s] (no new controller timestamp) that faults the arm; a real controller sends every 2 ms.
    stream_timeout: float = Field(default=0.5, gt=0, le=5)
    # The controller stops the program when the servo loop is silent for 1/watchdog_hz [s].
    watchdog_hz: float = Field(default=10.0, ge=1, le=500)


class DynamixelGripperConfig(StrictModel):
    """A gripper on a Dynamixel servo (protocol 2.0, current-based position mode)."""

    driver: Literal["dynamixel"]
    port: str = Field(min_length=1)  # e.g. /dev/ttyUSB0, or "auto" on the fake rig
    servo_id: int = Field(default=1, ge=0, le=252)
    baudrate: Literal[9600, 57600, 115200, 1000000, 2000000, 3000000, 4000000] = 57600
    ticks_closed: int = Field(ge=0, le=4095)  # Present_Position with the fingers closed
    ticks_open: int = Field(ge=0, le=4095)  # … and fully open
    current_limit_ma: float = Field(default=300.0, gt=0, le=6000)  # Goal_Current cap: the grasp force
    poll_hz: float = Field(default=100.0, gt=0, le=1000)  # the I/O thread's read/write rate
    timeout: float = Field(default=0.04, gt=0, le=5)  # wait for a status packet [s]

    @model_validator(mode="after")
    def _distinct(self) -> DynamixelGripperConfig:
        if self.ticks_open == self.ticks_closed:
            raise ValueError(f"ticks_open and ticks_closed must differ (both {self.ticks_open})")
        return self


class RobotiqGripperConfig(StrictModel):
    """A Robotiq 2F-85/140 over Modbus RTU (RS-485 adapter)."""

    driver: Literal["robotiq"]
    port: str = Field(min_length=1)
    slave_id: int = Field(default=9, ge=1, le=247)
    baudrate: int = Field(default=115200, gt=0)
    speed: int = Field(default=255, ge=0, le=255)
    force: int = Field(default=150, ge=0, le=255)
    position_open: int = Field(default=0, ge=0, le=255)  # position request with the fingers fully open
    position_closed: int = Field(default=255, ge=0, le=255)
    poll_hz: float = Field(default=50.0, gt=0, le=500)  # the I/O thread's read/write rate
    timeout: float = Field(default=0.1, gt=0, le=5)  # wait for a reply [s]

    @model_validator(mode="after")
    def _distinct(self) -> RobotiqGripperConfig:
        if self.position_open == self.position_closed:
            raise ValueError(f"position_open and position_closed must differ (both {self.position_open})")
        return self


GripperDriverConfig = Annotated[DynamixelGripperConfig | RobotiqGripperConfig, Field(discriminator="driver")]


class CameraDriverConfig(StrictModel):
    """An OpenCV camera: a device index or a stream URL (``auto`` on the fake rig)."""

    source: int | str
    width: int | None = Field(default=None, gt=0)
    height: int | None = Field(default=None, gt=0)
    fps: float | None = Field(default=None, gt=0)
    reconnect: bool = False


class StreamSize(StrictModel):
    """The size of the frames a fake camera streams (its "full resolution")."""

    width: int = Field(gt=0, le=4096)
    height: int = Field(gt=0, le=4096)


class FakeRigConfig(StrictModel):
    """Start the protocol fakes backed by the simulated rig (mocked-hardware CI, demos without a robot)."""

    task: str = "sort_cubes"  # the simulated scene behind the fakes
    camera_fps: float = Field(default=15.0, gt=0, le=60)
    # Per camera, the size of the frames its fake streams (a real camera's full resolution), rendered with
    # the rig camera's field of view, so the intrinsics scale exactly; the drivers letterbox them to the rig's
    # image_size for the policy. Unlisted cameras stream at image_size. Calibration grabs the full frames.
    stream_sizes: dict[str, StreamSize] = Field(default_factory=dict)
    # Loopback addresses of the two fake UR controllers (RTDE's port is fixed, so one address per arm).
    left_host: str = "127.0.0.1"
    right_host: str = "127.0.0.2"

    @field_validator("left_host", "right_host")
    @classmethod
    def _loopback(cls, value: str) -> str:
        if not ipaddress.ip_address(value).is_loopback:
            raise ValueError(f"fake controllers listen on loopback (127.0.0.0/8) only, got {value}")
        return value


class ArmDrivers(StrictModel):
    left: URArmDriverConfig
    right: URArmDriverConfig


class GripperDrivers(StrictModel):
    left: GripperDriverConfig
    right: GripperDriverConfig


class HardwareConfig(StrictModel):
    arms: ArmDrivers
    grippers: GripperDrivers
    cameras: dict[str, CameraDriverConfig]
    max_age: float = Field(default=0.25, gt=0, le=5)  # observations older than this are refused [s]
    start_speed: float = Field(default=0.3, gt=0, le=1.0)  # joint speed of the move to a start pose [rad/s]
    # The 14-d pose every subtask starts from (arm joints in rad, grips 0 closed … 1 open); None: the
    # arms start wherever they stand when the operator confirms the scene.
    start_pose: tuple[float, ...] | None = None
    fake: FakeRigConfig | None = None

    @field_validator("start_pose")
    @classmethod
    def _pose(cls, value: tuple[float, ...] | None) -> tuple[float, ...] | None:
        if value is not None and len(value) != 14:
            raise ValueError(f"start_pose: expected 14 values (two arms of 6 joints and 2 grips), got {len(value)}")
        return value

    @model_validator(mode="after")
    def _auto_only_on_fakes(self) -> HardwareConfig:
        if self.fake is None:
            autos = [f"grippers.{s}.port" for s in ("left", "right") if getattr(self.grippers, s).port == AUTO]
            autos += [f"cameras.{c}.source" for c, cam in self.cameras.items() if cam.source == AUTO]
            if autos:
                raise ValueError(f"{', '.join(autos)}: 'auto' is only meaningful with a 'fake:' section")
        return self
