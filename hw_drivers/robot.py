"""The ``Robot`` contract every backend implements (real dual-arm rig, simulated rig, protocol fakes).

A robot is connected, observed and commanded one control step at a time:

* ``observe()`` returns an :class:`~pilworld.types.Observation` (every camera of ``spec.cameras`` plus the
  measured 14-d state);
* ``send_action(a)`` commands one absolute 14-d target and returns what was actually sent (after
  clamping), so a caller can record the truth rather than its request (LeRobot's convention).

Errors are typed and carry the device name, so a caller can stop safely and tell the user what broke.
"""

from __future__ import annotations

from types import TracebackType
from typing import Protocol, runtime_checkable

import numpy as np
from numpy.typing import NDArray

from hw_drivers.errors import DeviceAlreadyConnectedError, DeviceNotConnectedError, RobotError
from pilworld.types import Observation, RobotSpec

__all__ = ["DeviceAlreadyConnectedError", "DeviceNotConnectedError", "Robot", "RobotError"]


@runtime_checkable
class Robot(Protocol):
    """A robot seen by the rollout code: spec, connection, observations and absolute joint commands."""

    @property
    def spec(self) -> RobotSpec: ...

    @property
    def is_connected(self) -> bool: ...

    def connect(self) -> None: ...

    def disconnect(self) -> None: ...

    def observe(self) -> Observation: ...

    def send_action(self, action: NDArray[np.floating]) -> NDArray[np.float32]: ...

    def __enter__(self) -> Robot: ...

    def __exit__(
        self, exc_type: type[BaseException] | None, exc: BaseException | None, tb: TracebackType | None
    ) -> None: ...
