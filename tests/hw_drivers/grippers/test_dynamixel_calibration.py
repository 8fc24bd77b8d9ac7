"""The ticks ↔ opening mapping of a servo gripper."""

from __future__ import annotations

import math

import pytest

from hw_drivers.grippers.calibration import TickMapping


@pytest.mark.parametrize(("closed", "opened"), [(2048, 3048), (3000, 1000), (0, 4095)])
def test_linear_both_directions(closed: int, opened: int) -> None:
    m = TickMapping(closed, opened)
    assert m.to_ticks(0.0) == closed and m.to_ticks(1.0) == opened
    assert m.to_opening(closed) == 0.0 and m.to_opening(opened) == 1.0
    mid = m.to_ticks(0.25)
    assert mid == round(closed + 0.25 * (opened - closed))
    assert m.to_opening(mid) == pytest.approx(0.25, abs=1 / abs(opened - closed))
    for ticks in range(min(closed, opened), max(closed, opened) + 1, 97):
        assert m.to_ticks(m.to_opening(ticks)) == ticks


def test_clipping() -> None:
    m = TickMapping(3000, 2000)  # mounted the other way round
    assert m.to_ticks(-0.5) == 3000 and m.to_ticks(7.0) == 2000
    assert m.to_opening(3100) == 0.0 and m.to_opening(1900) == 1.0
    assert m.to_opening(3100, clip=False) == pytest.approx(-0.1)
    with pytest.raises(ValueError, match="NaN"):
        m.to_ticks(math.nan)


@pytest.mark.parametrize(
    ("closed", "opened", "match"),
    [
        (2048, 2048, "must differ"),
        (-1, 2048, "ticks_closed"),
        (2048, 4096, "ticks_open"),
        (2048.0, 3000, "ticks_closed"),
        (True, 3000, "ticks_closed"),
    ],
)
def test_validation(closed: object, opened: object, match: str) -> None:
    with pytest.raises(ValueError, match=match):
        TickMapping(closed, opened)  # type: ignore[arg-type]
