"""The camera contract: the latest frame with its capture time, refused when stale.

A driver captures in a background thread; :meth:`Camera.read_latest` never waits for the device
longer than the frame's allowed age, and raises ``StaleObservationError`` rather than hand the
policy an old frame.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Protocol, runtime_checkable

import numpy as np
from numpy.typing import NDArray


@dataclass(frozen=True)
class Frame:
    image: NDArray[np.uint8]  # (H, W, 3) RGB
    timestamp: float  # time.monotonic() when the frame was captured (received)
    index: int  # frames captured since connect(), from 0


@runtime_checkable
class Camera(Protocol):
    @property
    def name(self) -> str: ...

    @property
    def is_connected(self) -> bool: ...

    def connect(self) -> None:
        """Open the source and wait for the first frame (bounded by a timeout)."""
        ...

    def disconnect(self) -> None: ...

    def read_latest(self, max_age: float = 0.2) -> Frame:
        """The newest frame; raises ``StaleObservationError`` if it is older than ``max_age`` seconds."""
        ...
