"""What a render of the robot from its own model holds, whichever backend drew it."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray


@dataclass(frozen=True, eq=False)
class RobotRender:
    """Renders of N joint vectors in each view (all arrays have N on axis 0).

    ``parts``: uint8 part ids (0 background, 1 left arm, 2 left fingers, 3 right arm, 4 right fingers;
    :data:`~pilworld.control_video.robot_model.PART_NAMES`). ``depth``: float32 camera-frame depth Z in
    metres, 0 where there is no robot. ``shaded``: uint8 RGB, the robot lit by a headlight on black.
    ``depth`` and ``shaded`` are None when not asked for.
    """

    parts: dict[str, NDArray[np.uint8]]  # view → (N, H, W)
    depth: dict[str, NDArray[np.float32]] | None = None  # view → (N, H, W)
    shaded: dict[str, NDArray[np.uint8]] | None = None  # view → (N, H, W, 3)

    @property
    def views(self) -> tuple[str, ...]:
        return tuple(self.parts)

    @property
    def mask(self) -> dict[str, NDArray[np.bool_]]:
        """view → (N, H, W) True where the robot is."""
        return {v: p > 0 for v, p in self.parts.items()}
