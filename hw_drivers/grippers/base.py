"""The gripper contract: a normalised opening in, the measured opening out, never blocking the arm.

Opening is the normalised finger gap of the 14-d state (:mod:`pilworld.types`): 0 closed … 1 open.
A driver owns a background I/O thread that writes the latest target and polls the device; the calls
below only exchange values with that thread, so the arm's control loop never waits on a serial bus.
An I/O failure in the thread is stored and raised (typed, :mod:`hw_drivers.errors`) by the next call.
"""

from __future__ import annotations

import math
import statistics
from collections.abc import Iterable
from dataclasses import dataclass
from typing import Protocol, runtime_checkable


@dataclass(frozen=True)
class GripperStatus:
    """One reading of a gripper."""

    opening: float  # measured, 0 closed … 1 open
    target: float  # the last target sent to the device
    object_detected: bool  # the fingers stopped on something (Robotiq gOBJ 1/2; Dynamixel: current at the cap)
    fault: str  # "" or the device's fault, decoded
    timestamp: float  # time.monotonic() of the reading


@dataclass(frozen=True)
class RoundTripStats:
    """Round trips of a driver's polling read (request written → reply parsed): how long the bus takes."""

    count: int
    median_ms: float  # NaN before the first
    p99_ms: float

    @classmethod
    def from_seconds(cls, samples: Iterable[float]) -> RoundTripStats:
        s = sorted(samples)
        if not s:
            return cls(0, math.nan, math.nan)
        p99 = s[min(len(s) - 1, math.ceil(0.99 * len(s)) - 1)]
        return cls(len(s), statistics.median(s) * 1e3, p99 * 1e3)


@runtime_checkable
class Gripper(Protocol):
    @property
    def name(self) -> str: ...

    @property
    def is_connected(self) -> bool: ...

    def connect(self) -> None:
        """Open the port, check the device answers, configure it (torque on / activation), start the I/O thread."""
        ...

    def disconnect(self) -> None:
        """Stop the I/O thread and release the device (torque off / leave activated); idempotent."""
        ...

    def set_target(self, opening: float) -> float:
        """Queue a new target (non-blocking); returns it clipped to 0 … 1. Raises on a stored I/O error."""
        ...

    def status(self, max_age: float = 0.2) -> GripperStatus:
        """The latest reading; raises ``StaleObservationError`` if it is older than ``max_age`` seconds."""
        ...
