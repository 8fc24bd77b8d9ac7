"""A task file's object → the simulator's geoms, and the geometry the predicates and policies need.

Origins: solids (box, cylinder, sphere, capsule, compound, mesh) have their body origin at their centre;
open containers (bowl, cup, open box) at the centre of their underside, so they rest at z = 0.

:class:`Geometry` is what the rest of the task needs to know about a shape without looking at its geoms:
its vertical extent, its footprint, whether it is a container (and how deep something sits in it), and how
a parallel gripper holds it (pinched across the body, or by the rim of a container).
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass

from simrig.objects import Assets, GeomSpec, ObjectSpec, bowl_object, box_object, quat_axis_angle, quat_mul
from simrig.tasks import schema as s
from simrig.tasks.mesh import load_mesh_parts
from simrig.tasks.textures import texture_assets

Quat = tuple[float, float, float, float]
GRASP_Z = 0.022  # TCP height above an object's underside for a pinch low on the body [m] (fingertips 4 mm up)
PALM_CLEARANCE = 0.034  # the palm sits this far above the TCP, less a margin: the TCP stays this far below the top


@dataclass(frozen=True)
class Container:
    """The inside of an open container, relative to its underside: where content rests and how wide it is."""

    floor: float  # height of the inner floor [m]
    rim: float  # height of the rim's top [m]
    inner_radius: float  # inner radius at the floor (a box: its smaller inner half-size) [m]
    slope: float  # dr/dz of the inner wall (0 for a vertical wall)
    opening: float  # inner radius at the rim [m]

    def seat(self, base_radius: float) -> float:
        """Height of the underside of an object of footprint ``base_radius`` resting inside [m] (inf: too wide)."""
        if base_radius <= self.inner_radius:
            return self.floor
        if self.slope <= 0:
            return math.inf
        rise = (base_radius - self.inner_radius) / self.slope
        return self.floor + rise if self.floor + rise < self.rim else math.inf


@dataclass(frozen=True)
class Grasp:
    """How the scripted skill holds an object.

    ``pinch``: top-down, the fingers closing across the body at ``height`` above the underside; ``width``
    is the span across the narrower side, ``symmetry`` the yaw period of that side (π/2 square, π oblong,
    0 round). ``rim``: the fingers pinch the wall of a container at ``radius`` from its centre.
    """

    kind: str  # pinch | rim
    height: float  # TCP height above the object's underside [m]
    width: float
    symmetry: float
    radius: float = 0.0
    long_axis_yaw: float = 0.0  # for oblong objects: the yaw of the long side in the object frame [rad]


@dataclass(frozen=True)
class Geometry:
    """Shape facts, relative to the body origin (z up)."""

    bottom: float  # distance from the origin down to the lowest point
    top: float  # from the origin up to the highest point
    mid: float  # height (above the origin) where its image centroid is back-projected
    base_radius: float  # footprint at the underside (what rests on a floor or a flaring wall)
    radius: float  # largest horizontal distance from the vertical axis through the origin
    grasp: Grasp
    container: Container | None = None

    @property
    def height(self) -> float:
        return self.bottom + self.top


@dataclass(frozen=True)
class BuiltObject:
    spec: ObjectSpec
    geometry: Geometry
    rgb: tuple[float, float, float]  # the object's mean colour (for finding it in images)


def _rgba(rgb: tuple[float, float, float]) -> tuple[float, float, float, float]:
    return (rgb[0], rgb[1], rgb[2], 1.0)


def _axis_quat(axis: str) -> Quat:
    if axis == "x":
        return quat_axis_angle((0.0, 1.0, 0.0), math.pi / 2)
    if axis == "y":
        return quat_axis_angle((1.0, 0.0, 0.0), math.pi / 2)
    return (1.0, 0.0, 0.0, 0.0)


def _rpy_quat(rpy_deg: tuple[float, float, float]) -> Quat:
    r, p, y = (math.radians(v) for v in rpy_deg)
    q = quat_axis_angle((0.0, 0.0, 1.0), y)
    q = quat_mul(q, quat_axis_angle((0.0, 1.0, 0.0), p))
    return quat_mul(q, quat_axis_angle((1.0, 0.0, 0.0), r))


def _pinch(bottom: float, top: float, width: float, symmetry: float, long_yaw: float = 0.0) -> Grasp:
    height = max(GRASP_Z, bottom + top - PALM_CLEARANCE)
    return Grasp("pinch", height=height, width=width, symmetry=symmetry, long_axis_yaw=long_yaw)


def _extent(shape: str, dims: dict[str, float], quat: Quat) -> tuple[float, float, float, float]:
    """(z min, z max, max horizontal radius, footprint radius at the bottom) of a primitive at the origin."""
    pts: list[tuple[float, float, float]] = []
    if shape == "box":
        hx, hy, hz = dims["hx"], dims["hy"], dims["hz"]
        pts = [(sx * hx, sy * hy, sz * hz) for sx in (-1, 1) for sy in (-1, 1) for sz in (-1, 1)]
    else:
        r = dims["radius"]
        half = dims.get("half", 0.0)
        ring = [(r * math.cos(a), r * math.sin(a)) for a in (2 * math.pi * k / 16 for k in range(16))]
        if shape == "cylinder":
            pts = [(x, y, z) for x, y in ring for z in (-half, half)]
        else:  # sphere, capsule: sample the surface
            for k in range(9):
                el = -math.pi / 2 + math.pi * k / 8
                for x, y in ring:
                    c, zz = math.cos(el), r * math.sin(el)
                    for z0 in (-half, half) if shape == "capsule" else (0.0,):
                        pts.append((x * c, y * c, zz + z0))
    rot = _rotate(quat)
    out = [rot(p) for p in pts]
    zs = [p[2] for p in out]
    zmin = min(zs)
    radius = max(math.hypot(p[0], p[1]) for p in out)
    base = max((math.hypot(p[0], p[1]) for p in out if p[2] < zmin + 1e-3), default=0.0)
    return zmin, max(zs), radius, base


def _rotate(q: Quat):  # type: ignore[no-untyped-def]
    w, x, y, z = q

    def apply(p: tuple[float, float, float]) -> tuple[float, float, float]:
        px, py, pz = p
        # v' = q v q*, expanded
        tx, ty, tz = 2 * (y * pz - z * py), 2 * (z * px - x * pz), 2 * (x * py - y * px)
        return (
            px + w * tx + (y * tz - z * ty),
            py + w * ty + (z * tx - x * tz),
            pz + w * tz + (x * ty - y * tx),
        )

    return apply


def _primitive_geom(
    shape: str, dims: dict[str, float], rgba: tuple[float, ...], pos: tuple[float, float, float], quat: Quat
) -> GeomSpec:
    if shape == "box":
        size: tuple[float, ...] = (dims["hx"], dims["hy"], dims["hz"])
    elif shape in ("cylinder", "capsule"):
        size = (dims["radius"], dims["half"])
    else:
        size = (dims["radius"],)
    return GeomSpec(shape, size, (rgba[0], rgba[1], rgba[2], 1.0), pos=pos, quat=quat)


def _part_dims(part: s.Part | s.CylinderObject | s.SphereObject | s.CapsuleObject) -> dict[str, float]:
    """Half-sizes (box) or radius and half length (cylinder, capsule) or radius (sphere) of a primitive."""
    size: tuple[float, float, float] | None = getattr(part, "size", None)
    radius: float | None = getattr(part, "radius", None)
    if part.shape == "box":
        assert size is not None
        return {"hx": size[0] / 2, "hy": size[1] / 2, "hz": size[2] / 2}
    assert radius is not None
    along: float | None = getattr(part, "height" if part.shape == "cylinder" else "length", None)
    if part.shape in ("cylinder", "capsule"):
        assert along is not None
        return {"radius": radius, "half": along / 2}
    return {"radius": radius}


def build_object(obj: s.ObjectDef) -> BuiltObject:
    """The object's geoms (with its texture and mesh assets) and its :class:`Geometry`."""
    rgb = obj.colour if obj.colour is not None else (0.6, 0.6, 0.6)
    assets = Assets()
    material = None
    spec, geometry = _shape(obj, rgb)
    if obj.texture is not None:
        extent = max(2 * geometry.radius, geometry.height)
        assets, material, rgb = texture_assets(obj.name, obj.texture, obj.colour, extent=extent)
    if material is not None:  # the texture carries the colour; white keeps it unchanged
        geoms = tuple(dataclasses.replace(g, material=material, rgba=(1.0, 1.0, 1.0, 1.0)) for g in spec.geoms)
        spec = dataclasses.replace(spec, geoms=geoms)
    spec = dataclasses.replace(spec, assets=spec.assets + assets)
    return BuiltObject(spec=spec, geometry=geometry, rgb=(float(rgb[0]), float(rgb[1]), float(rgb[2])))


def _shape(obj: s.ObjectDef, rgb: tuple[float, float, float]) -> tuple[ObjectSpec, Geometry]:
    rgba = _rgba(rgb)
    if isinstance(obj, s.BoxObject):
        x, y, z = obj.size
        spec = box_object(obj.name, (x / 2, y / 2, z / 2), rgba, obj.mass, friction=obj.friction)
        narrow, wide = min(x, y), max(x, y)
        oblong = wide > 1.15 * narrow
        grasp = _pinch(z / 2, z / 2, narrow, math.pi if oblong else math.pi / 2, 0.0 if x >= y else math.pi / 2)
        geo = Geometry(z / 2, z / 2, 0.0, math.hypot(x, y) / 2, math.hypot(x, y) / 2, grasp)
        return spec, geo
    if isinstance(obj, s.BowlObject | s.CupObject):
        if isinstance(obj, s.BowlObject):
            rb, rt, h, wall, lip = obj.bottom_radius, obj.top_radius, obj.height, obj.wall, obj.lip
        else:
            rb = rt = obj.radius
            h, wall, lip = obj.height, obj.wall, 0.0
        spec = bowl_object(
            obj.name,
            bottom_radius=rb,
            top_radius=rt,
            height=h,
            rgba=rgba,
            mass=obj.mass,
            wall=wall,
            lip=lip,
            friction=obj.friction,
        )
        slope = (rt - rb) / (h - lip)
        container = Container(floor=wall, rim=h + wall, inner_radius=rb - wall, slope=slope, opening=rt - wall)
        # The fingertips just above the lip's bottom (bowl) or ~2 cm down the wall (cup).
        band = lip if lip > 0 else min(0.02, h / 2)
        grasp = Grasp("rim", height=h - band + wall / 2 + 0.004 + 0.018, width=wall, symmetry=0.0, radius=rt)
        return spec, Geometry(0.0, h + wall, h / 2, rb, rt + wall / 2, grasp, container)
    if isinstance(obj, s.OpenBoxObject):
        return _open_box(obj, rgba)
    if isinstance(obj, s.CylinderObject | s.SphereObject | s.CapsuleObject):
        dims = _part_dims(obj)
        quat = _axis_quat(obj.axis) if isinstance(obj, s.CylinderObject | s.CapsuleObject) else (1.0, 0.0, 0.0, 0.0)
        geom = _primitive_geom(obj.shape, dims, rgba, (0.0, 0.0, 0.0), quat)
        zmin, zmax, radius, base = _extent(obj.shape, dims, quat)
        axis = "z" if isinstance(obj, s.SphereObject) else obj.axis
        lying = axis != "z"
        width = 2 * dims["radius"]
        sym = math.pi if lying else 0.0
        long_yaw = 0.0 if (lying and axis == "x") else math.pi / 2
        grasp = _pinch(-zmin, zmax, width, sym, long_yaw)
        spec = ObjectSpec(obj.name, (geom,), obj.mass, obj.friction, bottom=-zmin, top=zmax)
        return spec, Geometry(-zmin, zmax, 0.0, base, radius, grasp)
    if isinstance(obj, s.CompoundObject):
        return _compound(obj, rgba)
    assert isinstance(obj, s.MeshObject)
    return _mesh(obj, rgba)


def _open_box(obj: s.OpenBoxObject, rgba: tuple[float, float, float, float]) -> tuple[ObjectSpec, Geometry]:
    x, y, z = obj.size
    w = obj.wall
    geoms = [GeomSpec("box", (x / 2, y / 2, w / 2), rgba, pos=(0.0, 0.0, w / 2))]
    hz = (z - w) / 2
    zc = w + hz
    geoms += [GeomSpec("box", (w / 2, y / 2, hz), rgba, pos=(sx * (x / 2 - w / 2), 0.0, zc)) for sx in (-1.0, 1.0)]
    geoms += [GeomSpec("box", (x / 2 - w, w / 2, hz), rgba, pos=(0.0, sy * (y / 2 - w / 2), zc)) for sy in (-1.0, 1.0)]
    spec = ObjectSpec(obj.name, tuple(geoms), obj.mass, obj.friction, bottom=0.0, top=z)
    inner = min(x, y) / 2 - w
    container = Container(floor=w, rim=z, inner_radius=inner, slope=0.0, opening=inner)
    # Pinch the middle of a long wall: its centre lies half the box's depth across from the TCP.
    band = min(0.02, (z - w) / 2)
    grasp = Grasp("rim", height=z - band + 0.018, width=w, symmetry=0.0, radius=min(x, y) / 2 - w / 2)
    return spec, Geometry(0.0, z, z / 2, math.hypot(x, y) / 2, math.hypot(x, y) / 2, grasp, container)


def _compound(obj: s.CompoundObject, rgba: tuple[float, float, float, float]) -> tuple[ObjectSpec, Geometry]:
    geoms = []
    zmin = zmax = 0.0
    radius = 0.0
    ext: list[tuple[float, float, float, float]] = []
    for part in obj.parts:
        prgba = _rgba(part.colour) if part.colour is not None else rgba
        dims = _part_dims(part)
        quat = _rpy_quat(part.rpy_deg)
        geoms.append(_primitive_geom(part.shape, dims, prgba, part.pos, quat))
        lo, hi, r, _ = _extent(part.shape, dims, quat)
        px, py, pz = part.pos
        ext.append((pz + lo, pz + hi, math.hypot(px, py) + r, r))
    zmin = min(e[0] for e in ext)
    zmax = max(e[1] for e in ext)
    radius = max(e[2] for e in ext)
    g = obj.parts[obj.grasp_part]
    gd = _part_dims(g)
    glo, _, _, _ = _extent(g.shape, gd, _rpy_quat(g.rpy_deg))
    if g.shape == "box":
        width = min(2 * gd["hx"], 2 * gd["hy"])
        sym = math.pi / 2 if abs(gd["hx"] - gd["hy"]) < 0.15 * max(gd["hx"], gd["hy"]) else math.pi
        long_yaw = 0.0 if gd["hx"] >= gd["hy"] else math.pi / 2
    else:
        width, sym, long_yaw = 2 * gd["radius"], 0.0, 0.0
    # Pinch the grasp part, low enough to keep the palm above the whole object.
    grasp = _pinch(-zmin, zmax, width, sym, long_yaw)
    grasp = dataclasses.replace(grasp, height=max(grasp.height, (g.pos[2] + glo) - zmin + 0.012))
    spec = ObjectSpec(obj.name, tuple(geoms), obj.mass, obj.friction, bottom=-zmin, top=zmax)
    base = max((e[3] for e in ext if e[0] < zmin + 1e-3), default=radius)
    return spec, Geometry(-zmin, zmax, (zmax + zmin) / 2, base, radius, grasp)


def _mesh(obj: s.MeshObject, rgba: tuple[float, float, float, float]) -> tuple[ObjectSpec, Geometry]:
    parts = load_mesh_parts(obj.file, obj.scale)
    geoms = []
    xml = []
    files = []
    for k, part in enumerate(parts.parts):
        name = f"{obj.name}_mesh{k}"
        fname = f"{name}.stl"
        xml.append(f'<mesh name="{name}" file="{fname}"/>')
        files.append((fname, part.stl))
        geoms.append(GeomSpec("mesh", (), rgba, mesh=name, volume=part.volume))
    (x0, y0, z0), (x1, y1, z1) = parts.bounds
    width = min(x1 - x0, y1 - y0)
    oblong = max(x1 - x0, y1 - y0) > 1.15 * width
    grasp = _pinch(-z0, z1, width, math.pi if oblong else math.pi / 2, 0.0 if (x1 - x0) >= (y1 - y0) else math.pi / 2)
    spec = ObjectSpec(
        obj.name, tuple(geoms), obj.mass, obj.friction, bottom=-z0, top=z1, assets=Assets(tuple(xml), tuple(files))
    )
    return spec, Geometry(-z0, z1, 0.0, parts.base_radius, parts.radius, grasp)
