"""Calibration of a servo gripper: encoder ticks ↔ normalised opening (0 closed … 1 open), linear.

A gripper is calibrated by reading the servo's Present_Position with the fingers closed and fully open
(``ticks_closed``, ``ticks_open``). Either direction is fine: a servo mounted the other way round simply
has ``ticks_open < ticks_closed``.
"""

from __future__ import annotations

from dataclasses import dataclass

TICKS_MAX = 4095  # one turn of a 12-bit Dynamixel encoder (position modes 3 and 5)


@dataclass(frozen=True)
class TickMapping:
    ticks_closed: int
    ticks_open: int

    def __post_init__(self) -> None:
        for name in ("ticks_closed", "ticks_open"):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, int) or not 0 <= value <= TICKS_MAX:
                raise ValueError(f"{name}: expected an integer in 0 … {TICKS_MAX}, got {value!r}")
        if self.ticks_open == self.ticks_closed:
            raise ValueError(f"ticks_open and ticks_closed must differ (both {self.ticks_open})")

    @property
    def span(self) -> int:
        """Signed ticks from closed to open."""
        return self.ticks_open - self.ticks_closed

    def to_ticks(self, opening: float) -> int:
        """The goal for ``opening`` (clipped to 0 … 1): always between the two calibrated ends."""
        if opening != opening:  # NaN would otherwise round to an arbitrary goal
            raise ValueError("opening: NaN")
        clipped = min(1.0, max(0.0, float(opening)))
        return round(self.ticks_closed + clipped * self.span)

    def to_opening(self, ticks: int, *, clip: bool = True) -> float:
        """The opening at ``ticks``; clipped to 0 … 1 unless ``clip=False`` (to see a calibration drift)."""
        opening = (ticks - self.ticks_closed) / self.span
        return min(1.0, max(0.0, opening)) if clip else opening
