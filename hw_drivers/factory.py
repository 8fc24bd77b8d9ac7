"""Build a :class:`~hw_drivers.dual_arm.DualArmRobot` from a rig file's ``hardware:`` section.

Drivers are imported only when a rig names them, so a machine without a serial adapter or a UR arm
can still load any rig file. On the fake rig, the ``auto`` ports and sources are replaced by the
fakes' endpoints (:class:`hw_drivers.fakes.rig.FakeEndpoints`).
"""

from __future__ import annotations

import dataclasses
from typing import TYPE_CHECKING

from hw_drivers.arm import Arm
from hw_drivers.cameras.base import Camera
from hw_drivers.dual_arm import DualArmRobot
from hw_drivers.grippers.base import Gripper
from hw_drivers.safety import dual_arm_speed_caps
from pilworld.config.hardware import AUTO, DynamixelGripperConfig, HardwareConfig
from pilworld.config.rig import RigConfig

if TYPE_CHECKING:
    from hw_drivers.fakes.rig import FakeEndpoints

SIDES = ("left", "right")


def _hardware(rig: RigConfig) -> HardwareConfig:
    if rig.hardware is None:
        raise ValueError(
            f"rig {rig.name!r} has no 'hardware:' section: it is the simulated rig (use it directly), "
            "or add the drivers (see configs/rig/real_dual_ur5e.yaml)"
        )
    return rig.hardware


def gripper_port(rig: RigConfig, side: str, endpoints: FakeEndpoints | None = None) -> str:
    """The serial port of the ``side`` gripper: as configured, or the fake rig's pty for ``auto``."""
    port = str(getattr(_hardware(rig).grippers, side).port)
    if port != AUTO:
        return port
    if endpoints is None:
        raise ValueError(f"hardware.grippers.{side}.port is 'auto' but no fake rig is running")
    return endpoints.gripper_ports[side]


def camera_source(rig: RigConfig, name: str, endpoints: FakeEndpoints | None = None) -> int | str:
    """The source of camera ``name``: as configured, or the fake rig's MJPEG stream for ``auto``."""
    source = _hardware(rig).cameras[name].source
    if source != AUTO:
        return source
    if endpoints is None:
        raise ValueError(f"hardware.cameras.{name}.source is 'auto' but no fake rig is running")
    return endpoints.camera_urls[name]


def build_arms(rig: RigConfig, endpoints: FakeEndpoints | None = None) -> dict[str, Arm]:
    from hw_drivers.ur.arm import URArm

    hw = _hardware(rig)
    arms: dict[str, Arm] = {}
    for side in SIDES:
        cfg = getattr(hw.arms, side)
        host = endpoints.arm_hosts[side] if endpoints is not None else cfg.host
        arms[side] = URArm(
            f"{side} arm",
            host,
            servo_rate_hz=cfg.servo_rate_hz,
            lookahead_time=cfg.lookahead_time,
            gain=cfg.gain,
            connect_timeout=cfg.connect_timeout,
            retries=cfg.retries,
            max_joint_speed=cfg.max_joint_speed,
            stream_timeout=cfg.stream_timeout,
            watchdog_hz=cfg.watchdog_hz,
        )
    return arms


def build_grippers(rig: RigConfig, endpoints: FakeEndpoints | None = None) -> dict[str, Gripper]:
    hw = _hardware(rig)
    grippers: dict[str, Gripper] = {}
    for side in SIDES:
        cfg = getattr(hw.grippers, side)
        port = gripper_port(rig, side, endpoints)
        if isinstance(cfg, DynamixelGripperConfig):
            from hw_drivers.grippers.dynamixel import DynamixelGripper

            grippers[side] = DynamixelGripper(
                f"{side} gripper",
                port,
                cfg.servo_id,
                baudrate=cfg.baudrate,
                ticks_closed=cfg.ticks_closed,
                ticks_open=cfg.ticks_open,
                current_limit_ma=cfg.current_limit_ma,
                poll_hz=cfg.poll_hz,
                timeout=cfg.timeout,
            )
        else:
            from hw_drivers.grippers.robotiq import RobotiqGripper

            grippers[side] = RobotiqGripper(
                f"{side} gripper",
                port,
                slave_id=cfg.slave_id,
                baudrate=cfg.baudrate,
                speed=cfg.speed,
                force=cfg.force,
                position_open=cfg.position_open,
                position_closed=cfg.position_closed,
                poll_hz=cfg.poll_hz,
                timeout=cfg.timeout,
            )
    return grippers


def build_cameras(rig: RigConfig, endpoints: FakeEndpoints | None = None) -> dict[str, Camera]:
    from hw_drivers.cameras.opencv import OpenCVCamera

    hw = _hardware(rig)
    cameras: dict[str, Camera] = {}
    for name in rig.cameras:
        cfg = hw.cameras[name]
        cameras[name] = OpenCVCamera(
            name,
            camera_source(rig, name, endpoints),
            width=cfg.width,
            height=cfg.height,
            fps=cfg.fps,
            reconnect=cfg.reconnect,
        )
    return cameras


def build_robot(rig: RigConfig, endpoints: FakeEndpoints | None = None) -> DualArmRobot:
    """The rig's robot (not yet connected): two UR arms, two grippers and the cameras."""
    hw = _hardware(rig)
    # The same joint speed caps as the simulated rig: a UR e-Series joint's maximum, and a full
    # gripper stroke in 0.5 s. The safety filter slows every command to them.
    spec = dataclasses.replace(rig.robot_spec(), max_joint_speed=dual_arm_speed_caps())
    return DualArmRobot(
        spec,
        build_arms(rig, endpoints),
        build_grippers(rig, endpoints),
        build_cameras(rig, endpoints),
        max_age=hw.max_age,
        name=rig.name,
    )
