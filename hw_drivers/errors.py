"""Typed errors of the hardware layer. Every error names the device (``device``) that failed.

A caller (the paired runner, ``pilworld robot check``) catches :class:`RobotError`, stops the robot and
tells the user what broke; tests assert on the subclass. Nothing in ``hw_drivers`` falls back silently
to a fake or a default when a device misbehaves: it raises one of these.
"""

from __future__ import annotations


class RobotError(RuntimeError):
    """Base class of robot errors; ``device`` names the part that failed."""

    def __init__(self, device: str, message: str) -> None:
        super().__init__(f"{device}: {message}")
        self.device = device


class DeviceNotConnectedError(RobotError):
    """An operation needed a connected device (call ``connect()`` or use the robot as a context manager)."""


class DeviceAlreadyConnectedError(RobotError):
    """``connect()`` was called twice."""


class DeviceConnectionError(RobotError):
    """Could not connect (after the configured retries), or the connection was lost."""


class DeviceTimeoutError(RobotError):
    """A device did not answer (or a stream delivered nothing) within its time bound."""


class DeviceProtocolError(RobotError):
    """Replies were malformed (bad checksum, wrong length or id) more often than the retries allow."""


class DeviceFaultError(RobotError):
    """The device itself reports a fault (a gripper fault code, a servo hardware error)."""


class SafetyStopError(RobotError):
    """The robot controller stopped the arm for safety; it must be recovered explicitly."""


class ProtectiveStopError(SafetyStopError):
    """A protective stop (collision, limit violation): recover through the dashboard (unlock)."""


class EmergencyStopError(SafetyStopError):
    """An emergency stop: released by a person on the robot, never by software."""


class StaleObservationError(RobotError):
    """An observation (frame or joint reading) is older than allowed."""


class SafetyViolationError(RobotError):
    """The safety filter refused a command; the robot was stopped. ``check`` names the rule."""

    def __init__(self, device: str, check: str, message: str) -> None:
        super().__init__(device, f"{check}: {message}")
        self.check = check
