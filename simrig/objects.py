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

    type: str  # box | cylinder | sphere | capsule | mesh
    size: tuple[float, ...]
    rgba: Rgba
    pos: Vec3 = (0.0, 0.0, 0.0)
    quat: tuple[float, float, float, float] = (1.0, 0.0, 0.0, 0.0)  # (w, x, y, z)
    collide: bool = True
    material: str | None = None  # a material asset (a texture), see ``Assets``
    mesh: str | None = None  # the mesh asset of a ``mesh`` geom
    volume: float | None = None  # of a mesh geom (its convex hull) [m³]; primitives compute their own


@dataclass(frozen=True)
class Assets:
    """MJCF ``<asset>`` lines (textures, materials, meshes) and the bytes of the files they name."""

    xml: tuple[str, ...] = ()
    files: tuple[tuple[str, bytes], ...] = ()

    def __add__(self, other: Assets) -> Assets:
        return Assets(self.xml + other.xml, self.files + other.files)


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
    assets: Assets = Assets()


@dataclass(frozen=True)
class FixtureSpec:
    """A static decoration or obstacle fixed to the table (e.g. a slot outline)."""

    name: str
    geoms: tuple[GeomSpec, ...]
    pos: Vec3 = (0.0, 0.0, 0.0)
    quat: tuple[float, float, float, float] = (1.0, 0.0, 0.0, 0.0)
    assets: Assets = Assets()


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


def quat_axis_angle(axis: Vec3, angle: float) -> tuple[float, float, float, float]:
    s = math.sin(angle / 2.0)
    return (math.cos(angle / 2.0), axis[0] * s, axis[1] * s, axis[2] * s)


def quat_mul(a: tuple[float, ...], b: tuple[float, ...]) -> tuple[float, float, float, float]:
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
    lip: float = 0.015,
    segments: int = 12,
    friction: float = 1.0,
) -> ObjectSpec:
    """A bowl: a base disc, ``segments`` wall plates flaring from ``bottom_radius`` to ``top_radius``, and
    a vertical lip of height ``lip`` on top.

    The body origin is at the centre of the base's underside, so the bowl rests at z = 0 on the table.
    The lip is what a parallel gripper pinches: vertical pads on a slanted wall would only touch its
    edges and let the bowl swing in the hand. Plates are slightly wider than the polygon edge so
    neighbouring plates overlap and the wall has no gaps a finger could slip through.
    """
    if not 0 < bottom_radius <= top_radius:
        raise ValueError(f"{name}: need 0 < bottom_radius <= top_radius, got {bottom_radius}, {top_radius}")
    if not 0 <= lip < height:
        raise ValueError(f"{name}: need 0 <= lip < height, got lip={lip}, height={height}")
    geoms = [GeomSpec("cylinder", (bottom_radius, wall / 2), rgba, pos=(0.0, 0.0, wall / 2))]
    body_h = height - lip  # height of the flaring part
    flare = math.atan2(top_radius - bottom_radius, body_h)  # tilt of each plate away from vertical
    slant = math.hypot(top_radius - bottom_radius, body_h)
    mid_r = (bottom_radius + top_radius) / 2.0
    half_width = 1.08 * math.pi * mid_r / segments  # half the polygon edge at mid height, plus overlap
    lip_half_width = 1.08 * math.pi * top_radius / segments
    for i in range(segments):
        phi = 2.0 * math.pi * i / segments
        # Plate frame: z along the slant, x radial, y tangential; yaw by phi, then tilt about the
        # tangential axis so the top leans outwards (a positive turn about +y moves +z towards +x).
        q_yaw = quat_axis_angle((0.0, 0.0, 1.0), phi)
        quat = quat_mul(q_yaw, quat_axis_angle((0.0, 1.0, 0.0), flare))
        c, s = math.cos(phi), math.sin(phi)
        pos = (mid_r * c, mid_r * s, body_h / 2.0 + wall / 2)
        geoms.append(GeomSpec("box", (wall / 2, half_width, slant / 2), rgba, pos=pos, quat=quat))
        if lip > 0:
            lip_pos = (top_radius * c, top_radius * s, body_h + lip / 2.0 + wall / 2)
            geoms.append(GeomSpec("box", (wall / 2, lip_half_width, lip / 2 + 0.002), rgba, pos=lip_pos, quat=q_yaw))
    return ObjectSpec(
        name=name,
        geoms=tuple(geoms),
        mass=mass,
        friction=friction,
        bottom=0.0,
        top=height + wall,
        extra={"bottom_radius": bottom_radius, "top_radius": top_radius, "height": height, "wall": wall, "lip": lip},
    )
