"""What the pose planner (:mod:`pilworld.calibration.plan`) samples and how it filters, per camera mount.

The two mounts sample different things, so their settings differ in the sampling region:
:class:`PlannerSettings` places the *board* (held by the gripper) in front of the fixed head camera,
:class:`WristPlannerSettings` places the *camera* (on the wrist) above the board fixed on the table. How
many poses, the image margin, the view angle, the clearance and the spread metric are the same filters for
both, validated once (:func:`_validate`). Metres and degrees, rig frame (docs/calibration.md, "3. Hand-eye"
and "Wrist cameras (eye-in-hand)").
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

__all__ = ["PlannerSettings", "WristPlannerSettings"]


def _range(value: tuple[float, float], label: str) -> tuple[float, float]:
    lo, hi = (float(v) for v in value)
    if not (math.isfinite(lo) and math.isfinite(hi) and lo <= hi):
        raise ValueError(f"{label}: expected (low, high) with low <= high, got {value!r}")
    return lo, hi


def _validate(
    s: Any,
    label: str,
    ranges: tuple[str, ...],
    optional_range: str,
    metres: tuple[str, ...],
    sampling: Callable[[], None] = lambda: None,
) -> None:
    """Check (and normalise to float pairs) the settings ``s``; errors name ``label`` and the field.

    ``ranges`` are (low, high) fields, ``optional_range`` one that may be None, ``metres`` fields that must
    be >= 0, and ``sampling`` checks what only one mount's sampling needs, after the ranges.
    """
    for name in ("poses", "candidates"):
        value = getattr(s, name)
        if isinstance(value, bool) or not isinstance(value, int) or value < 1:
            raise ValueError(f"{label} {name}: expected an integer >= 1, got {value!r}")
    for name in ranges:
        object.__setattr__(s, name, _range(getattr(s, name), f"{label} {name}"))
    if getattr(s, optional_range) is not None:
        object.__setattr__(s, optional_range, _range(getattr(s, optional_range), f"{label} {optional_range}"))
    sampling()
    if not 0.0 <= s.image_margin < 0.5:
        raise ValueError(f"{label} image_margin: expected a fraction in [0, 0.5), got {s.image_margin!r}")
    for name in ("max_view_angle_deg", "position_weight_m", "max_arm_joint_move_rad"):
        if not float(getattr(s, name)) > 0.0:
            raise ValueError(f"{label} {name}: expected a positive number, got {getattr(s, name)!r}")
    for name in metres:
        if not float(getattr(s, name)) >= 0.0:
            raise ValueError(f"{label} {name}: expected metres >= 0, got {getattr(s, name)!r}")


@dataclass(frozen=True)
class PlannerSettings:
    """Eye-to-hand: board poses in front of the head camera, held by one arm; metres and degrees, rig frame."""

    poses: int = 20  #: board poses to choose (at least 3)
    candidates: int = 2000  #: candidate poses sampled before filtering
    region_x: tuple[float, float] = (-0.25, 0.25)  #: board-centre x range
    #: board-centre y range for the left arm (the right arm uses the mirror image, -high..-low)
    region_y: tuple[float, float] = (-0.08, 0.30)
    region_z: tuple[float, float] = (0.12, 0.45)  #: board-centre height above the table
    #: tilt of the board normal off the line of sight to the camera (a negative tilt leans the other way)
    tilt_deg: tuple[float, float] = (15.0, 35.0)
    #: direction of the tilt axis in the board plane (0 = the board's nominal x axis); None: any direction
    tilt_axis_deg: tuple[float, float] | None = None
    yaw_deg: tuple[float, float] = (-45.0, 45.0)  #: turn about the normal from the nominal in-plane direction
    #: start from a normal pointing at the camera from each sampled centre (True) or from the region's
    #: centre for every pose (False: then tilt and yaw alone set the orientation, e.g. to test degeneracy)
    face_camera: bool = True
    image_margin: float = 0.03  #: free border around the page, as a fraction of the image size
    max_view_angle_deg: float = 50.0  #: largest angle between a corner's line of sight and the board normal
    clearance_m: float = 0.015  #: extra clearance of lines of sight and of the plate from the arm capsules
    position_weight_m: float = 0.2  #: metres of board-centre distance that count as one radian of rotation
    max_arm_joint_move_rad: float = 2.0  #: largest move of the base, shoulder and elbow from the start joints

    def __post_init__(self) -> None:
        ranges = ("region_x", "region_y", "region_z", "tilt_deg", "yaw_deg")
        _validate(self, "planner", ranges, "tilt_axis_deg", ("clearance_m",))


@dataclass(frozen=True)
class WristPlannerSettings:
    """Eye-in-hand: wrist-camera poses above the board on the table; metres and degrees, rig frame."""

    poses: int = 20  #: arm poses to choose (at least 3)
    candidates: int = 2500  #: candidate camera poses sampled before filtering
    distance_m: tuple[float, float] = (0.30, 0.46)  #: camera centre to the aimed point
    tilt_deg: tuple[float, float] = (8.0, 35.0)  #: optical axis off the board normal
    roll_deg: tuple[float, float] = (-50.0, 50.0)  #: turn about the optical axis from the nominal orientation
    aim_offset_m: float = 0.03  #: the aimed point lies within this of the board centre (per axis, in its plane)
    #: image row (fraction of the height from the top) where the aimed point appears: above the gripper,
    #: which covers the bottom third of the simulated rig's wrist images
    aim_v: float = 0.33
    #: None: any tilt azimuth; (lo, hi): only these azimuths (degrees about the board normal from rig +x),
    #: e.g. to test degeneracy
    azimuth_deg: tuple[float, float] | None = None
    image_margin: float = 0.04  #: free border around the page, as a fraction of the image size
    max_view_angle_deg: float = 50.0  #: largest angle between a corner's line of sight and the board normal
    clearance_m: float = 0.015  #: extra clearance of the lines of sight from the arm capsules
    position_weight_m: float = 0.2  #: metres of camera distance that count as one radian of rotation
    max_arm_joint_move_rad: float = 2.0  #: largest move of the base, shoulder and elbow from the start joints

    def __post_init__(self) -> None:
        def sampling() -> None:
            if not self.distance_m[0] > 0.05:
                raise ValueError(f"wrist planner distance_m: expected metres > 0.05, got {self.distance_m!r}")
            if not 0.0 < self.aim_v < 1.0:
                raise ValueError(f"wrist planner aim_v: expected a fraction in (0, 1), got {self.aim_v!r}")

        ranges = ("distance_m", "tilt_deg", "roll_deg")
        _validate(self, "wrist planner", ranges, "azimuth_deg", ("clearance_m", "aim_offset_m"), sampling)
