"""How the control video looks: marker size ↔ gripper opening, colours per arm, trace fading.

The mapping (paper appendix "Control-Video Projection Details": marker size encodes the gripper's
open–close state; short fading traces encode motion continuity):

* marker radius in pixels ``r(g) = S · (radius_closed + (radius_open − radius_closed) · clip(g, 0, 1))``
  with ``S = min(width, height)`` and ``g`` the grip value (0 = closed … 1 = open). It is strictly
  increasing in ``g`` on [0, 1]; at 128×128 the defaults give 3.2 px (closed) … 8.96 px (open), at
  224×224 5.6 … 15.7 px. Grip values outside [0, 1] are clipped, so a policy that overshoots does
  not change the image scale the world model was trained on.
* left arm pure red, right arm pure blue (one colour channel each, so the two never mix; the
  marker is drawn at full brightness);
* the trace behind a marker in frame k joins the projected positions of frames k−L … k (L =
  ``trace_length`` segments); the segment of age j (0 = newest) is drawn at brightness
  ``(L − j) / (L + 1)`` of the arm's colour, so the trace fades out towards the past.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

RGB = tuple[int, int, int]


def _check_color(name: str, color: RGB) -> None:
    if len(color) != 3 or not all(isinstance(c, int) and 0 <= c <= 255 for c in color):
        raise ValueError(f"{name}: expected an RGB triple of integers 0..255, got {color!r}")


@dataclass(frozen=True)
class ControlVideoStyle:
    """Drawing parameters of Γ; defaults are what the world model is trained on, change both together."""

    radius_closed: float = 0.025  # marker radius at grip 0, as a fraction of min(width, height)
    radius_open: float = 0.07  # marker radius at grip 1, same unit
    trace_length: int = 3  # segments of fading trace behind each marker (0 = none)
    trace_width: float = 1.0 / 128  # trace thickness as a fraction of min(width, height) (≥ 1 px)
    left_color: RGB = (255, 0, 0)
    right_color: RGB = (0, 0, 255)
    antialias: bool = True  # sub-pixel, anti-aliased drawing (needed for ≤ 0.5 px marker accuracy)

    def __post_init__(self) -> None:
        if not 0 < self.radius_closed < self.radius_open <= 0.5:
            raise ValueError(
                "radius_closed/radius_open: need 0 < radius_closed < radius_open ≤ 0.5 (fractions of the "
                f"image size) so size grows strictly with opening, got {self.radius_closed}, {self.radius_open}"
            )
        if isinstance(self.trace_length, bool) or not isinstance(self.trace_length, int) or self.trace_length < 0:
            raise ValueError(f"trace_length: expected an integer ≥ 0, got {self.trace_length!r}")
        if not 0 < self.trace_width <= 0.1:
            raise ValueError(f"trace_width: expected a fraction in (0, 0.1], got {self.trace_width!r}")
        _check_color("left_color", self.left_color)
        _check_color("right_color", self.right_color)
        if self.left_color == self.right_color:
            raise ValueError("left_color/right_color: the two arms need distinct colours")

    @property
    def colors(self) -> tuple[RGB, RGB]:
        return self.left_color, self.right_color

    def marker_radius(self, grip: NDArray[np.floating] | float, width: int, height: int) -> NDArray[np.float64]:
        """Marker radius in pixels for grip values (any shape); strictly increasing on [0, 1]."""
        g = np.clip(np.asarray(grip, dtype=np.float64), 0.0, 1.0)
        return min(width, height) * (self.radius_closed + (self.radius_open - self.radius_closed) * g)

    def trace_fade(self) -> NDArray[np.float64]:
        """Brightness of trace segments by age 0 (newest) … L−1: (L − j) / (L + 1)."""
        L = self.trace_length
        return (L - np.arange(L, dtype=np.float64)) / (L + 1)

    def trace_thickness(self, width: int, height: int) -> int:
        return max(1, round(self.trace_width * min(width, height)))
