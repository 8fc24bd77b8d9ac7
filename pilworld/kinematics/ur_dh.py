"""Denavit–Hartenberg parameters of the Universal Robots arms (e-Series, UR20/UR30 and CB3).

Source: Universal Robots, "DH parameters for calculations of kinematics and dynamics", support
article on universal-robots.com,
https://www.universal-robots.com/articles/ur/application-installation/dh-parameters-for-calculations-of-kinematics-and-dynamics/

These are the *nominal* parameters. Every physical arm ships with a factory kinematic calibration
(stored on the controller) that deviates from them by up to a few millimetres, so sub-millimetre work
must use the per-robot values.

Convention (classic/standard DH, as published by UR): the transform from link frame ``i-1`` to link
frame ``i`` is ``T_i = Rz(theta_i) @ Tz(d_i) @ Tx(a_i) @ Rx(alpha_i)`` with ``theta_i = q_i`` (UR's
tables have no joint offsets). Frame 0 is the UR *base* frame (the controller's "Base" feature,
which is rotated 180 deg about z relative to the ``base_link`` of ROS URDFs) and frame 6 is the tool
flange with z pointing out of it (``tool0`` in ROS). Lengths are in metres, angles in radians.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Final

import numpy as np

from pilworld.geometry import FloatArray

__all__ = [
    "UR_DEFAULT_JOINT_LIMITS",
    "UR_MODELS",
    "DHParams",
    "Vec6",
    "dh_params",
]

Vec6 = tuple[float, float, float, float, float, float]

_HALF_PI: Final = math.pi / 2
# Identical for every UR model: shoulder and wrist 1 axes are parallel to the base z, etc.
_UR_ALPHA: Final[Vec6] = (_HALF_PI, 0.0, 0.0, _HALF_PI, -_HALF_PI, 0.0)

# The controller accepts +-2 pi (+-360 deg) on every joint of CB3 and e-Series arms (and UR20/UR30).
# Many cells restrict the elbow to +-pi because the upper and lower arm collide beyond that, but that
# is a per-installation safety setting, not an arm property, so the defaults use the controller range.
UR_DEFAULT_JOINT_LIMITS: Final[tuple[tuple[float, float], ...]] = ((-2 * math.pi, 2 * math.pi),) * 6


@dataclass(frozen=True)
class DHParams:
    """Nominal classic-DH table of a 6-joint arm.

    Attributes:
        name: canonical lower-case model name, e.g. ``"ur5e"``.
        d: link offsets along the previous z axis, metres, one per joint.
        a: link lengths along the new x axis, metres, one per joint.
        alpha: link twists about the new x axis, radians, one per joint.
        joint_limits: ``(lower, upper)`` per joint in radians.
    """

    name: str
    d: Vec6
    a: Vec6
    alpha: Vec6
    joint_limits: tuple[tuple[float, float], ...] = UR_DEFAULT_JOINT_LIMITS

    def __post_init__(self) -> None:
        # Validate once at construction so FK never has to re-check the table.
        for field_name in ("d", "a", "alpha"):
            values = getattr(self, field_name)
            if len(values) != 6 or not all(math.isfinite(float(v)) for v in values):
                raise ValueError(f"DHParams.{field_name} must be 6 finite floats; got {values!r}")
        if len(self.joint_limits) != 6 or not all(
            len(lim) == 2 and math.isfinite(lim[0]) and math.isfinite(lim[1]) and lim[0] < lim[1]
            for lim in self.joint_limits
        ):
            raise ValueError(
                f"DHParams.joint_limits must be 6 finite (lower, upper) pairs with lower < upper; "
                f"got {self.joint_limits!r}"
            )

    @property
    def d_array(self) -> FloatArray:
        """``d`` as a float64 array of shape ``(6,)`` [m]."""
        return np.array(self.d, dtype=np.float64)

    @property
    def a_array(self) -> FloatArray:
        """``a`` as a float64 array of shape ``(6,)`` [m]."""
        return np.array(self.a, dtype=np.float64)

    @property
    def alpha_array(self) -> FloatArray:
        """``alpha`` as a float64 array of shape ``(6,)`` [rad]."""
        return np.array(self.alpha, dtype=np.float64)

    @property
    def lower_limits(self) -> FloatArray:
        """Lower joint limits, float64 ``(6,)`` [rad]."""
        return np.array([lim[0] for lim in self.joint_limits], dtype=np.float64)

    @property
    def upper_limits(self) -> FloatArray:
        """Upper joint limits, float64 ``(6,)`` [rad]."""
        return np.array([lim[1] for lim in self.joint_limits], dtype=np.float64)


def _ur(name: str, d1: float, a2: float, a3: float, d4: float, d5: float, d6: float) -> DHParams:
    # UR tables only ever have these six non-zero lengths; a2 and a3 are negative because the upper
    # and lower arm point along -x of their link frames at q = 0.
    return DHParams(
        name=name,
        d=(d1, 0.0, 0.0, d4, d5, d6),
        a=(0.0, a2, a3, 0.0, 0.0, 0.0),
        alpha=_UR_ALPHA,
    )


_TABLE: Final[dict[str, DHParams]] = {
    p.name: p
    for p in (
        # e-Series
        _ur("ur3e", d1=0.15185, a2=-0.24355, a3=-0.2132, d4=0.13105, d5=0.08535, d6=0.0921),
        _ur("ur5e", d1=0.1625, a2=-0.425, a3=-0.3922, d4=0.1333, d5=0.0997, d6=0.0996),
        _ur("ur10e", d1=0.1807, a2=-0.6127, a3=-0.57155, d4=0.17415, d5=0.11985, d6=0.11655),
        _ur("ur16e", d1=0.1807, a2=-0.4784, a3=-0.36, d4=0.17415, d5=0.11985, d6=0.11655),
        # UR20 / UR30 (no "e" suffix, same DH structure)
        _ur("ur20", d1=0.2363, a2=-0.862, a3=-0.7287, d4=0.201, d5=0.1593, d6=0.1543),
        _ur("ur30", d1=0.2363, a2=-0.637, a3=-0.5037, d4=0.201, d5=0.1593, d6=0.1543),
        # CB3
        _ur("ur3", d1=0.1519, a2=-0.24365, a3=-0.21325, d4=0.11235, d5=0.08535, d6=0.0819),
        _ur("ur5", d1=0.089159, a2=-0.425, a3=-0.39225, d4=0.10915, d5=0.09465, d6=0.0823),
        _ur("ur10", d1=0.1273, a2=-0.612, a3=-0.5723, d4=0.163941, d5=0.1157, d6=0.0922),
    )
}

UR_MODELS: Final[tuple[str, ...]] = tuple(_TABLE)
"""Canonical model names accepted by :func:`dh_params`."""

# CB3 arms are often written with an explicit series suffix to tell them apart from e-Series.
_ALIASES: Final[dict[str, str]] = {f"{base}{sep}cb3": base for base in ("ur3", "ur5", "ur10") for sep in ("_", "")}


def dh_params(name: str) -> DHParams:
    """Nominal DH table for a UR model, looked up case-insensitively (``"UR5e"``, ``"ur5_cb3"``, ...).

    Raises:
        ValueError: if ``name`` is not a known model; the message lists the valid names.
    """
    if not isinstance(name, str):
        raise TypeError(f"name must be a str such as 'ur5e'; got {type(name).__name__}")
    key = name.strip().lower().replace("-", "_")
    key = _ALIASES.get(key, key)
    try:
        return _TABLE[key]
    except KeyError:
        valid = ", ".join(UR_MODELS)
        aliases = ", ".join(sorted(a for a in _ALIASES if "_" in a))
        raise ValueError(
            f"unknown UR model name {name!r}; valid names (case-insensitive) are: {valid} (CB3 aliases: {aliases})"
        ) from None
