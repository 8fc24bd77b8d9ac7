"""The arm contract the dual-arm robot composes: measured joints, a streamed target, a capped move.

Joint angles in radians, 6 per arm. :meth:`Arm.set_target` is non-blocking: the arm's servo loop
(500 Hz for a UR arm) interpolates toward the latest target. A safety stop of the controller raises
``ProtectiveStopError`` / ``EmergencyStopError`` from the next call; :meth:`Arm.recover` clears a
protective stop explicitly (never automatically).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Protocol, runtime_checkable

import numpy as np
from numpy.typing import NDArray


@dataclass(frozen=True)
class ArmState:
    q: NDArray[np.float64]  # measured joint angles (6,) [rad]
    qd: NDArray[np.float64]  # measured joint velocities (6,) [rad/s]
    timestamp: float  # time.monotonic() when it was received
    safety: str  # "normal", "protective_stop", "emergency_stop", ... (decoded safety_status_bits)


@runtime_checkable
class Arm(Protocol):
    @property
    def name(self) -> str: ...

    @property
    def is_connected(self) -> bool: ...

    def connect(self) -> None: ...

    def disconnect(self) -> None:
        """Stop servoing (servoStop), stop the script, close the connections; idempotent."""
        ...

    def state(self, max_age: float = 0.1) -> ArmState:
        """The latest reading; ``StaleObservationError`` if older than ``max_age``; safety stops raise."""
        ...

    def set_target(self, q: NDArray[np.floating]) -> None:
        """Stream a new joint target (non-blocking); the servo loop interpolates toward it."""
        ...

    def move_to(self, q: NDArray[np.floating], speed: float, timeout: float) -> None:
        """Move to ``q`` at no more than ``speed`` rad/s on any joint, blocking until there (or raising)."""
        ...

    def stop(self) -> None:
        """Stop moving now (decelerate and hold); idempotent, safe to call from any state."""
        ...

    def recover(self) -> None:
        """Clear a protective stop through the dashboard (unlock, restart the control script)."""
        ...
