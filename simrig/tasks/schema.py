"""The task file's schema (``configs/tasks/*.yaml``), validated on load; every field is documented in docs/tasks.md.

A task is data, written once: the instruction and the subtasks with their goals as predicates, and for the
simulated rig the objects (shape, size, mass, friction, colour or texture), fixtures, named regions and the
layout sampler. After LIBERO's and BEHAVIOR's BDDL files (objects, regions, an initial condition, a goal as
a logical expression of predicates), as YAML for a dual-arm tabletop rig. Lengths are metres, angles degrees.

The models here check one field at a time; what needs the whole file (names that must exist, a container
that must hold its content, a layout that must fit) is checked in :mod:`simrig.tasks.checks`.
"""

from __future__ import annotations

import re
from pathlib import Path
from typing import Annotated, Any, Literal

from pydantic import Field, ValidationInfo, field_validator, model_validator

from pilworld.config.loader import StrictModel

NAME_RE = re.compile(r"^[a-z][a-z0-9_]{0,39}$")
Length = Annotated[float, Field(gt=0.0, le=0.5)]  # one object dimension [m]
Coord = tuple[float, float]
Range = tuple[float, float]
MAX_OBJECTS = 12
MAX_SUBTASKS = 20
PREDICATES = ("all", "any", "in_region", "on", "inside", "upright", "on_table")


def check_name(value: str, what: str = "name") -> str:
    if not isinstance(value, str) or not NAME_RE.match(value):
        raise ValueError(f"{what} must be lower-case letters, digits and '_', starting with a letter (≤ 40 characters)")
    return value


def parse_colour(value: Any) -> tuple[float, float, float]:
    """``[r, g, b]`` in 0..1 or ``"#rrggbb"`` → three floats in 0..1."""
    if isinstance(value, str):
        m = re.fullmatch(r"#?([0-9a-fA-F]{6})", value.strip())
        if not m:
            raise ValueError("a colour is [r, g, b] with values in 0..1 or a hex string '#rrggbb'")
        h = m.group(1)
        return (int(h[0:2], 16) / 255.0, int(h[2:4], 16) / 255.0, int(h[4:6], 16) / 255.0)
    if isinstance(value, list | tuple) and len(value) in (3, 4):
        try:
            rgb = tuple(float(v) for v in value[:3])
        except (TypeError, ValueError):
            rgb = (-1.0, -1.0, -1.0)
        if all(0.0 <= c <= 1.0 for c in rgb):
            return (rgb[0], rgb[1], rgb[2])
    raise ValueError("a colour is [r, g, b] with values in 0..1 or a hex string '#rrggbb'")


def resolve_file(value: str, info: ValidationInfo, kinds: tuple[str, ...], what: str) -> str:
    """A file named in the task file, relative to its folder; it must exist and have one of ``kinds``."""
    path = Path(value).expanduser()
    base = (info.context or {}).get("base_dir")
    if not path.is_absolute() and base is not None:
        path = Path(base) / path
    if path.suffix.lower() not in kinds:
        raise ValueError(f"{what} must be an {' or '.join(k.lstrip('.').upper() for k in kinds)} file, got {value!r}")
    if not path.is_file():
        raise ValueError(f"{what} not found: {path}")
    return str(path)


class Texture(StrictModel):
    """An image file, or a procedural pattern, wrapped around the object (``scale`` metres per period)."""

    image: str | None = None  # PNG or JPEG, relative to the task file
    pattern: Literal["checker", "stripes", "dots", "noise", "wood"] | None = None
    colours: tuple[Any, Any] | None = None  # the pattern's two colours; default: the object colour, lighter/darker
    scale: float = Field(default=0.02, gt=0.001, le=0.5)

    @field_validator("image")
    @classmethod
    def _image(cls, value: str | None, info: ValidationInfo) -> str | None:
        return None if value is None else resolve_file(value, info, (".png", ".jpg", ".jpeg"), "texture image")

    @field_validator("colours")
    @classmethod
    def _colours(cls, value: Any) -> Any:
        return None if value is None else tuple(parse_colour(c) for c in value)

    @model_validator(mode="after")
    def _one(self) -> Texture:
        if (self.image is None) == (self.pattern is None):
            raise ValueError("give exactly one of 'image' (a file) or 'pattern' (checker, stripes, dots, noise, wood)")
        return self


class _Look(StrictModel):
    colour: Any = None  # [r, g, b] in 0..1 or "#rrggbb"
    texture: Texture | None = None

    @field_validator("colour")
    @classmethod
    def _colour(cls, value: Any) -> Any:
        return None if value is None else parse_colour(value)


class _ObjectBase(_Look):
    name: str
    mass: float = Field(gt=0.0, le=5.0)  # kg
    friction: float = Field(default=1.0, gt=0.0, le=3.0)  # sliding friction coefficient

    @field_validator("name")
    @classmethod
    def _name(cls, value: str) -> str:
        return check_name(value)

    @model_validator(mode="after")
    def _appearance(self) -> _ObjectBase:
        if self.colour is None and self.texture is None:
            raise ValueError("give a 'colour' or a 'texture' (a policy and a person find objects by their look)")
        return self


class BoxObject(_ObjectBase):
    shape: Literal["box"]
    size: tuple[Length, Length, Length]  # full extents x, y, z


class CylinderObject(_ObjectBase):
    shape: Literal["cylinder"]
    radius: Length
    height: Length
    axis: Literal["x", "y", "z"] = "z"  # z: standing; x or y: lying on its side


class SphereObject(_ObjectBase):
    shape: Literal["sphere"]
    radius: Length


class CapsuleObject(_ObjectBase):
    shape: Literal["capsule"]
    radius: Length
    length: Length  # of the cylindrical part, between the two half-spheres
    axis: Literal["x", "y", "z"] = "x"  # x or y: lying (a pill); z: standing


class BowlObject(_ObjectBase):
    """An open container, a surface of revolution: a base disc, a flaring wall and a vertical lip to pinch."""

    shape: Literal["bowl"]
    bottom_radius: Length
    top_radius: Length
    height: Length
    wall: float = Field(default=0.006, gt=0.0, le=0.05)
    lip: float = Field(default=0.015, ge=0.0, le=0.2)

    @model_validator(mode="after")
    def _geometry(self) -> BowlObject:
        if self.top_radius <= self.bottom_radius:
            raise ValueError(f"top_radius ({self.top_radius}) must exceed bottom_radius ({self.bottom_radius})")
        if self.lip >= self.height:
            raise ValueError(f"lip ({self.lip}) must be lower than height ({self.height})")
        if 2 * self.wall >= self.bottom_radius:
            raise ValueError(f"wall ({self.wall}) is too thick for bottom_radius {self.bottom_radius}")
        return self


class CupObject(_ObjectBase):
    """An open container with a vertical wall (a cup, a jar, a pot); pinched at its rim."""

    shape: Literal["cup"]
    radius: Length
    height: Length
    wall: float = Field(default=0.005, gt=0.0, le=0.05)

    @model_validator(mode="after")
    def _geometry(self) -> CupObject:
        if 2 * self.wall >= self.radius:
            raise ValueError(f"wall ({self.wall}) is too thick for radius {self.radius}")
        return self


class OpenBoxObject(_ObjectBase):
    """An open box (a tray, a bin): a floor and four walls; pinched at the middle of a wall."""

    shape: Literal["open_box"]
    size: tuple[Length, Length, Length]  # outer extents x, y, z
    wall: float = Field(default=0.005, gt=0.0, le=0.05)

    @model_validator(mode="after")
    def _geometry(self) -> OpenBoxObject:
        if 2 * self.wall >= min(self.size[0], self.size[1]) or self.wall >= self.size[2]:
            raise ValueError(f"wall ({self.wall}) is too thick for size {list(self.size)}")
        return self


class Part(_Look):
    """One primitive of a compound object, in the object's frame (origin at its centre, z up)."""

    shape: Literal["box", "cylinder", "sphere", "capsule"]
    size: tuple[Length, Length, Length] | None = None  # box: full extents
    radius: Length | None = None  # cylinder, sphere, capsule
    height: Length | None = None  # cylinder
    length: Length | None = None  # capsule: the cylindrical part
    pos: tuple[float, float, float] = (0.0, 0.0, 0.0)
    rpy_deg: tuple[float, float, float] = (0.0, 0.0, 0.0)

    @model_validator(mode="after")
    def _dims(self) -> Part:
        need = {
            "box": ("size",),
            "cylinder": ("radius", "height"),
            "sphere": ("radius",),
            "capsule": ("radius", "length"),
        }
        missing = [k for k in need[self.shape] if getattr(self, k) is None]
        extra = [k for k in ("size", "radius", "height", "length") if k not in need[self.shape] and getattr(self, k)]
        if missing:
            raise ValueError(f"a {self.shape} part needs {', '.join(missing)}")
        if extra:
            raise ValueError(f"a {self.shape} part takes {', '.join(need[self.shape])}, not {', '.join(extra)}")
        if max(abs(p) for p in self.pos) > 0.3:
            raise ValueError(f"part pos {list(self.pos)} is more than 0.3 m from the object's centre")
        return self


class CompoundObject(_ObjectBase):
    """Several primitives rigidly joined (a mug with a handle, an L-block); parts may carry their own look."""

    shape: Literal["compound"]
    parts: list[Part] = Field(min_length=1, max_length=16)
    grasp_part: int = Field(default=0, ge=0)  # the part a gripper pinches

    @model_validator(mode="after")
    def _grasp(self) -> CompoundObject:
        if self.grasp_part >= len(self.parts):
            raise ValueError(f"grasp_part {self.grasp_part} names no part (the object has {len(self.parts)})")
        return self


class MeshObject(_ObjectBase):
    """A closed triangle mesh (OBJ or STL); each connected part collides as its convex hull."""

    shape: Literal["mesh"]
    file: str
    scale: float = Field(default=1.0, gt=0.0, le=100.0)  # file units → metres

    @field_validator("file")
    @classmethod
    def _file(cls, value: str, info: ValidationInfo) -> str:
        return resolve_file(value, info, (".obj", ".stl"), "mesh file")


ObjectDef = Annotated[
    BoxObject
    | CylinderObject
    | SphereObject
    | CapsuleObject
    | BowlObject
    | CupObject
    | OpenBoxObject
    | CompoundObject
    | MeshObject,
    Field(discriminator="shape"),
]
SHAPES = ("box", "cylinder", "sphere", "capsule", "bowl", "cup", "open_box", "compound", "mesh")


class _FixtureBase(_Look):
    name: str
    centre: Coord
    yaw_deg: float = 0.0

    @field_validator("name")
    @classmethod
    def _name(cls, value: str) -> str:
        return check_name(value)


class OutlineFixture(_FixtureBase):
    """A flat rectangular outline on the table (a slot); visual only."""

    kind: Literal["outline"]
    size: tuple[Length, Length]  # inner width (x) and depth (y)
    line: float = Field(default=0.008, gt=0.0, le=0.05)


class RingFixture(_FixtureBase):
    """A flat circular mark on the table; visual only."""

    kind: Literal["ring"]
    radius: Length
    line: float = Field(default=0.008, gt=0.0, le=0.05)
    segments: int = Field(default=16, ge=6, le=64)


class PatchFixture(_FixtureBase):
    """A flat filled rectangle (``size``) or disc (``radius``) on the table (a mat, a target); visual only."""

    kind: Literal["patch"]
    size: tuple[Length, Length] | None = None
    radius: Length | None = None

    @model_validator(mode="after")
    def _one(self) -> PatchFixture:
        if (self.size is None) == (self.radius is None):
            raise ValueError("a patch takes exactly one of 'size' (a rectangle) or 'radius' (a disc)")
        return self


class PegFixture(_FixtureBase):
    """An upright cylinder fixed to the table; objects collide with it."""

    kind: Literal["peg"]
    radius: Length
    height: Length


class BlockFixture(_FixtureBase):
    """A box fixed to the table (a wall, a step, a shelf base); objects collide with it."""

    kind: Literal["block"]
    size: tuple[Length, Length, Length]


FixtureDef = Annotated[
    OutlineFixture | RingFixture | PatchFixture | PegFixture | BlockFixture, Field(discriminator="kind")
]


class Region(StrictModel):
    """A named area of the table: a rectangle (``half_size``) or a disc (``radius``) around ``centre``."""

    name: str
    centre: Coord
    half_size: tuple[Length, Length] | None = None
    radius: Length | None = None

    @field_validator("name")
    @classmethod
    def _name(cls, value: str) -> str:
        return check_name(value)

    @model_validator(mode="after")
    def _one(self) -> Region:
        if (self.half_size is None) == (self.radius is None):
            raise ValueError("a region takes exactly one of 'half_size' (a rectangle) or 'radius' (a disc)")
        return self


class Disc(StrictModel):
    centre: Coord
    radius: Length


def _check_range(value: Range, what: str) -> Range:
    if not value[0] <= value[1]:
        raise ValueError(f"{what} must be [low, high] with low ≤ high, got {list(value)}")
    return value


class Scatter(StrictModel):
    """Objects placed at random in a rectangle, pairwise ``min_distance`` apart, each with a random yaw."""

    objects: list[str] = Field(min_length=1)
    x: Range
    y: Range
    min_distance: float = Field(gt=0.0, le=1.0)
    shuffle: bool = False  # assign the drawn points to the objects in a random order
    yaw_deg: Range = (0.0, 0.0)
    keep_out: list[Disc] = Field(default_factory=list)

    @field_validator("x", "y", "yaw_deg")
    @classmethod
    def _range(cls, value: Range, info: ValidationInfo) -> Range:
        return _check_range(value, str(info.field_name))


class StartOn(StrictModel):
    """An object that starts on top of (``on``) or inside (``inside``) another one."""

    object: str
    on: str | None = None
    inside: str | None = None

    @model_validator(mode="after")
    def _one(self) -> StartOn:
        if (self.on is None) == (self.inside is None):
            raise ValueError("give exactly one of 'on' or 'inside'")
        return self


class Layout(StrictModel):
    seed_salt: int | None = Field(default=None, ge=0, lt=2**31)  # default: from the task's name
    keep_out: list[Disc] = Field(default_factory=list)  # for every scatter group
    scatter: list[Scatter] = Field(min_length=1)
    stacked: list[StartOn] = Field(default_factory=list)


class InRegion(StrictModel):
    region: str
    object: str | None = None  # default: the subtask's object


class OnTable(StrictModel):
    object: str | None = None
    height_tolerance: float = Field(default=0.006, gt=0.0, le=0.1)


class On(StrictModel):
    support: str
    object: str | None = None
    tolerance: float = Field(default=0.015, gt=0.0, le=0.2)  # horizontal offset of the centres [m]
    height_tolerance: float = Field(default=0.006, gt=0.0, le=0.1)


class Inside(StrictModel):
    container: str
    object: str | None = None
    tolerance: float = Field(default=0.02, gt=0.0, le=0.2)
    height_tolerance: float = Field(default=0.012, gt=0.0, le=0.1)


class Upright(StrictModel):
    object: str | None = None
    max_tilt_deg: float = Field(default=11.5, gt=0.0, le=90.0)


class Predicate(StrictModel):
    """One predicate, or a conjunction (``all``) or disjunction (``any``) of them: a mapping with one key."""

    all: list[Predicate] | None = None
    any: list[Predicate] | None = None
    in_region: InRegion | None = None
    on: On | None = None
    inside: Inside | None = None
    upright: Upright | None = None
    on_table: OnTable | None = None

    @model_validator(mode="before")
    @classmethod
    def _one_key(cls, data: Any) -> Any:
        if not isinstance(data, dict) or len(data) != 1:
            raise ValueError(f"a goal is a mapping with exactly one predicate (one of {', '.join(PREDICATES)})")
        ((key, value),) = data.items()
        if key not in PREDICATES:
            raise ValueError(f"unknown predicate {key!r} (allowed: {', '.join(PREDICATES)})")
        if key in ("all", "any") and not (isinstance(value, list) and value):
            raise ValueError(f"'{key}' takes a non-empty list of predicates")
        if key == "in_region" and isinstance(value, str):
            return {key: {"region": value}}
        if key == "on" and isinstance(value, str):
            return {key: {"support": value}}
        if key == "inside" and isinstance(value, str):
            return {key: {"container": value}}
        if key in ("upright", "on_table") and value is None:
            return {key: {}}
        return data

    @property
    def kind(self) -> str:
        return next(k for k in PREDICATES if getattr(self, k) is not None)


class Settle(StrictModel):
    """Stable after release: the scene runs on this long and the object must stay put and keep its goal."""

    seconds: float = Field(default=1.0, ge=0.0, le=10.0)
    max_motion: float = Field(default=0.01, gt=0.0, le=0.2)


class SubtaskDef(StrictModel):
    object: str | None = None  # the object this subtask moves (simulated rig)
    goal: Predicate | None = None
    settle: Settle = Settle()
    operator_setup: str = ""  # hardware: what the operator lays out before the subtask
    operator_success: str = ""  # hardware: what counts as success, for the operator's verdict


class TaskFile(StrictModel):
    """A whole task file. ``objects`` empty: a hardware-only task (instruction and operator notes)."""

    name: str
    instruction: str = Field(min_length=1, max_length=500)
    objects: list[ObjectDef] = Field(default=[], max_length=MAX_OBJECTS)
    fixtures: list[FixtureDef] = Field(default=[], max_length=32)
    regions: list[Region] = Field(default=[], max_length=32)
    layout: Layout | None = None
    subtasks: list[SubtaskDef] = Field(min_length=1, max_length=MAX_SUBTASKS)

    @field_validator("name")
    @classmethod
    def _name(cls, value: str) -> str:
        return check_name(value, "task name")

    @field_validator("instruction")
    @classmethod
    def _instruction(cls, value: str) -> str:
        if not value.strip():
            raise ValueError("the instruction must not be blank")
        return value

    @property
    def simulated(self) -> bool:
        """Whether the simulated rig can build this task (it names objects)."""
        return bool(self.objects)
