"""Task objects as MuJoCo primitives: boxes, and bowls built from several convex pieces.

MuJoCo collides convex shapes only, so a bowl is a flat disc plus a ring of thin wall plates tilted
outwards; that is enough for nesting, rim grasps and a stable stack. Everything is a primitive, so the
scene needs no mesh files and compiles in milliseconds.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

Vec3 = tuple[float, float, float]
Rgba = tuple[float, float, float, float]


@dataclass(frozen=True)
class GeomSpec:
    """One MuJoCo geom in its body's frame (``size`` as MJCF: half-sizes for a box)."""

    type: str  # box | cylinder | sphere | capsule
    size: tuple[float, ...]
    rgba: Rgba
    pos: Vec3 = (0.0, 0.0, 0.0)
    quat: tuple[float, float, float, float] = (1.0, 0.0, 0.0, 0.0)  # (w, x, y, z)
    collide: bool = True


@dataclass(frozen=True)
class ObjectSpec:
    """A free-moving task object: a name, its geoms and its total mass (spread by geom volume)."""

    name: str
    geoms: tuple[GeomSpec, ...]
    mass: float
    friction: float = 1.0
    # The object's own vertical extent, from its body origin down to its lowest point and up to its top.
    bottom: float = 0.0
    top: float = 0.0
    extra: dict[str, float] = field(default_factory=dict)  # task-specific dimensions (radius, size …)


@dataclass(frozen=True)
class FixtureSpec:
    """A static decoration or obstacle fixed to the table (e.g. a slot outline)."""

    name: str
    geoms: tuple[GeomSpec, ...]
    pos: Vec3 = (0.0, 0.0, 0.0)


def box_object(name: str, half: Vec3, rgba: Rgba, mass: float, friction: float = 1.0) -> ObjectSpec:
    """A box centred on its body origin."""
    return ObjectSpec(
        name=name,
        geoms=(GeomSpec("box", half, rgba),),
        mass=mass,
        friction=friction,
        bottom=half[2],
        top=half[2],
        extra={"size": 2 * half[0]},
    )


def _quat_axis_angle(axis: Vec3, angle: float) -> tuple[float, float, float, float]:
    s = math.sin(angle / 2.0)
    return (math.cos(angle / 2.0), axis[0] * s, axis[1] * s, axis[2] * s)


def _quat_mul(a: tuple[float, ...], b: tuple[float, ...]) -> tuple[float, float, float, float]:
    aw, ax, ay, az = a
    bw, bx, by, bz = b
    return (
        aw * bw - ax * bx - ay * by - az * bz,
        aw * bx + ax * bw + ay * bz - az * by,
        aw * by - ax * bz + ay * bw + az * bx,
        aw * bz + ax * by - ay * bx + az * bw,
    )


def bowl_object(
    name: str,
    *,
    bottom_radius: float,
    top_radius: float,
    height: float,
    rgba: Rgba,
    mass: float,
    wall: float = 0.006,
    segments: int = 12,
    friction: float = 1.0,
) -> ObjectSpec:
    """A bowl: a base disc and ``segments`` wall plates flaring from ``bottom_radius`` to ``top_radius``.

    The body origin is at the centre of the base's underside, so the bowl rests at z = 0 on the table.
    The plates are slightly wider than the polygon edge so neighbouring plates overlap and the wall
    has no gaps a rim or finger could slip through.
    """
    if not 0 < bottom_radius < top_radius:
        raise ValueError(f"{name}: need 0 < bottom_radius < top_radius, got {bottom_radius}, {top_radius}")
    geoms = [GeomSpec("cylinder", (bottom_radius, wall / 2), rgba, pos=(0.0, 0.0, wall / 2))]
    flare = math.atan2(top_radius - bottom_radius, height)  # tilt of each plate away from vertical
    slant = math.hypot(top_radius - bottom_radius, height)
    mid_r = (bottom_radius + top_radius) / 2.0
    half_width = 1.08 * math.pi * mid_r / segments  # half the polygon edge at mid height, plus overlap
    for i in range(segments):
        phi = 2.0 * math.pi * i / segments
        # Plate frame: z along the slant, x tangential, y radial; rotate about z by phi, then tilt about
        # the tangential axis so the top leans outwards.
        q_yaw = _quat_axis_angle((0.0, 0.0, 1.0), phi)
        q_tilt = _quat_axis_angle((0.0, 1.0, 0.0), flare)
        # In the yawed frame the radial direction is +x; tilting about +y by +flare leans the top to +x.
        quat = _quat_mul(q_yaw, q_tilt)
        pos = (mid_r * math.cos(phi), mid_r * math.sin(phi), height / 2.0 + wall / 2)
        geoms.append(GeomSpec("box", (wall / 2, half_width, slant / 2), rgba, pos=pos, quat=quat))
    return ObjectSpec(
        name=name,
        geoms=tuple(geoms),
        mass=mass,
        friction=friction,
        bottom=0.0,
        top=height + wall,
        extra={"bottom_radius": bottom_radius, "top_radius": top_radius, "height": height, "wall": wall},
    )
