"""``Task``: a loaded task file as the simulator uses it — scene content, seeded layout, goals, checker.

Following dm_control, each concern is its own method: the scene content (:meth:`Task.objects`,
:meth:`Task.fixtures`), the initial state (:meth:`Task.layout`), the state after earlier subtasks are
done (:meth:`Task.completed_poses`), and success (:meth:`Task.in_place`). "Released" and "stable for a
while" are checked by the simulator for every task alike (``SimRobot.check_subtask``, with the subtask's
``settle``). Everything comes from the file; nothing here knows a particular task.
"""

from __future__ import annotations

import functools
import hashlib
import math
import zlib
from collections.abc import Mapping
from pathlib import Path

import numpy as np

from simrig.objects import FixtureSpec, GeomSpec, ObjectSpec
from simrig.tasks import schema as s
from simrig.tasks.base import Layout, LayoutError, ObjectPose, PlacementCheck, sample_positions
from simrig.tasks.predicates import Evaluator, Placement, placement
from simrig.tasks.shapes import BuiltObject, Geometry, build_object
from simrig.tasks.textures import texture_assets

FLAT = 0.0006  # half-thickness of flat marks on the table [m]
# Containers (and whatever is set inside one) start 1 mm above their computed rest: the wall plates' seat is
# approximate, and a body started in contact may be pushed out of it.
CONTAINER_LIFT = 0.001


class Task:
    """One task file, ready for the simulator; build it with :func:`simrig.tasks.load_task`."""

    def __init__(self, spec: s.TaskFile, path: Path | None = None, digest: str = "") -> None:
        self.spec = spec
        self.path = path
        self.digest = digest or hashlib.sha256(spec.model_dump_json().encode()).hexdigest()
        self.name = spec.name
        self.instruction = spec.instruction
        self.num_subtasks = len(spec.subtasks)
        self._built: dict[str, BuiltObject] = {o.name: build_object(o) for o in spec.objects}
        self.regions = {r.name: r for r in spec.regions}
        self.evaluate = Evaluator(self.geometry, self.regions)
        self.salt = (
            spec.layout.seed_salt
            if spec.layout is not None and spec.layout.seed_salt is not None
            else zlib.crc32(spec.name.encode()) % 2**31
        )

    # ------------------------------------------------------------------ what the file says

    @property
    def simulated(self) -> bool:
        return self.spec.simulated

    @functools.cached_property
    def geometry(self) -> dict[str, Geometry]:
        return {name: b.geometry for name, b in self._built.items()}

    def colour(self, name: str) -> tuple[float, float, float]:
        """An object's mean colour (its texture's mean when textured)."""
        return self._built[name].rgb

    @property
    def object_names(self) -> tuple[str, ...]:
        return tuple(self._built)

    def subtask(self, index: int) -> s.SubtaskDef:
        self.check_index(index)
        return self.spec.subtasks[index]

    def goal_placement(self, index: int) -> Placement | None:
        """Where subtask ``index``'s goal puts its object (None: no placement predicate)."""
        sub = self.subtask(index)
        if sub.goal is None or sub.object is None:
            return None
        return placement(sub.goal, sub.object)

    def check_index(self, index: int) -> None:
        if isinstance(index, bool) or not isinstance(index, int) or not 0 <= index < self.num_subtasks:
            raise ValueError(f"subtask: {self.name} has subtasks 0..{self.num_subtasks - 1}, got {index!r}")

    # ------------------------------------------------------------------ scene content

    def objects(self) -> tuple[ObjectSpec, ...]:
        return tuple(b.spec for b in self._built.values())

    def fixtures(self) -> tuple[FixtureSpec, ...]:
        return tuple(_fixture(f) for f in self.spec.fixtures)

    # ------------------------------------------------------------------ layout

    def layout(self, seed: int) -> Layout:
        """The seeded initial arrangement: scatter groups in order, then objects that start on or in others."""
        layout = self.spec.layout
        if layout is None:
            raise ValueError(f"task {self.name!r} has no objects to lay out (a hardware-only task)")
        rng = np.random.default_rng([seed, self.salt])
        poses: dict[str, ObjectPose] = {}
        rest: dict[str, float] = {}
        for g, group in enumerate(layout.scatter):
            keep_out = [(d.centre[0], d.centre[1], d.radius) for d in (*layout.keep_out, *group.keep_out)]
            keep_out += [(p.xyz[0], p.xyz[1], group.min_distance) for p in poses.values()]
            n = len(group.objects)
            try:
                xy = sample_positions(
                    rng, n, x_range=group.x, y_range=group.y, min_distance=group.min_distance, keep_out=tuple(keep_out)
                )
            except RuntimeError as exc:
                raise LayoutError(g, f"task {self.name!r}, layout.scatter.{g}, seed {seed}: {exc}") from None
            order = rng.permutation(n) if group.shuffle else np.arange(n)
            lo, hi = (math.radians(v) for v in group.yaw_deg)
            for name, k in zip(group.objects, order, strict=True):
                x, y = xy[int(k)]
                yaw = float(rng.uniform(lo, hi)) if hi > lo else lo
                poses[name] = ObjectPose.yawed(x, y, self.geometry[name].bottom, yaw)
        for start in layout.stacked:
            kind, target = ("on", start.on) if start.on is not None else ("inside", start.inside)
            assert target is not None
            poses[start.object] = self._resting(start.object, Placement(kind, target, 0.0), poses, rest)
        goals = {r.name: (r.centre[0], r.centre[1], 0.0) for r in self.spec.regions}
        return Layout(seed=seed, poses=poses, goals=goals)

    def subtask_object(self, index: int) -> str:
        sub = self.subtask(index)
        if sub.object is None:
            raise ValueError(f"task {self.name!r}: subtask {index} names no object (a hardware-only task)")
        return sub.object

    def _resting(
        self, name: str, where: Placement, poses: Mapping[str, ObjectPose], rest: dict[str, float]
    ) -> ObjectPose:
        """``name`` at rest where ``where`` says, given the other objects' ``poses``; ``rest`` holds each placed
        object's underside height at rest (without the lift it was given) and gains ``name``'s."""
        geo = self.geometry[name]
        lift = CONTAINER_LIFT if (geo.container is not None or where.kind == "inside") else 0.0
        if where.kind == "region":
            cx, cy = self.regions[where.target].centre
            rest[name] = 0.0
            return ObjectPose((cx, cy, geo.bottom + lift))
        below = poses[where.target]
        bgeo = self.geometry[where.target]
        base = rest.get(where.target, below.xyz[2] - bgeo.bottom)
        if where.kind == "on":
            rest[name] = base + bgeo.height
            return ObjectPose((below.xyz[0], below.xyz[1], rest[name] + geo.bottom + lift), below.quat)
        assert bgeo.container is not None
        rest[name] = base + bgeo.container.seat(geo.base_radius)
        return ObjectPose((below.xyz[0], below.xyz[1], rest[name] + geo.bottom + lift))

    def completed_poses(self, layout: Layout, done: int) -> dict[str, ObjectPose]:
        """Object poses once subtasks ``0 … done−1`` have succeeded (the others as in ``layout``)."""
        return self._complete(dict(layout.poses), done)[0]

    def done_heights(self) -> dict[str, float]:
        """Each subtask object's underside height once its subtask is done (objects left alone rest at 0)."""
        poses = {n: ObjectPose((0.0, 0.0, g.bottom)) for n, g in self.geometry.items()}
        rest = self._complete(poses, self.num_subtasks)[1]
        return {n: rest.get(n, 0.0) for n in self.geometry}

    def _complete(self, poses: dict[str, ObjectPose], done: int) -> tuple[dict[str, ObjectPose], dict[str, float]]:
        rest: dict[str, float] = {}
        for k in range(done):
            where = self.goal_placement(k)
            if where is None:
                raise ValueError(
                    f"task {self.name!r}: subtask {k}'s goal says nowhere to put its object (in_region, on or inside), "
                    "so later subtasks cannot start with it done"
                )
            poses[self.subtask_object(k)] = self._resting(self.subtask_object(k), where, poses, rest)
        return poses, rest

    # ------------------------------------------------------------------ success

    def in_place(self, layout: Layout, poses: Mapping[str, ObjectPose], index: int) -> PlacementCheck:
        """Whether subtask ``index``'s goal holds for ``poses`` (released and stable are checked by the simulator)."""
        sub = self.subtask(index)
        if sub.goal is None or sub.object is None:
            raise ValueError(f"task {self.name!r}: subtask {index} has no goal the simulator can check")
        return self.evaluate(sub.goal, poses, sub.object)


def _fixture(f: s.FixtureDef) -> FixtureSpec:
    rgb = f.colour if f.colour is not None else (0.25, 0.25, 0.27)
    rgba = (rgb[0], rgb[1], rgb[2], 1.0)
    geoms: list[GeomSpec] = []
    if isinstance(f, s.OutlineFixture):
        bar = f.line / 2
        hx, hy = f.size[0] / 2, f.size[1] / 2
        geoms = [
            GeomSpec("box", (hx + bar, bar, FLAT), rgba, pos=(0.0, hy + bar, FLAT), collide=False),
            GeomSpec("box", (hx + bar, bar, FLAT), rgba, pos=(0.0, -hy - bar, FLAT), collide=False),
            GeomSpec("box", (bar, hy + bar, FLAT), rgba, pos=(hx + bar, 0.0, FLAT), collide=False),
            GeomSpec("box", (bar, hy + bar, FLAT), rgba, pos=(-hx - bar, 0.0, FLAT), collide=False),
        ]
    elif isinstance(f, s.RingFixture):
        r, n = f.radius, f.segments
        for i in range(n):
            phi = 2 * math.pi * i / n
            quat = (math.cos(phi / 2), 0.0, 0.0, math.sin(phi / 2))
            pos = (r * math.cos(phi), r * math.sin(phi), FLAT)
            geoms.append(GeomSpec("box", (f.line / 2, math.pi * r / n, FLAT), rgba, pos=pos, quat=quat, collide=False))
    elif isinstance(f, s.PatchFixture):
        if f.radius is not None:
            geoms = [GeomSpec("cylinder", (f.radius, FLAT), rgba, pos=(0.0, 0.0, FLAT), collide=False)]
        else:
            assert f.size is not None
            geoms = [GeomSpec("box", (f.size[0] / 2, f.size[1] / 2, FLAT), rgba, pos=(0.0, 0.0, FLAT), collide=False)]
    elif isinstance(f, s.PegFixture):
        geoms = [GeomSpec("cylinder", (f.radius, f.height / 2), rgba, pos=(0.0, 0.0, f.height / 2))]
    else:
        assert isinstance(f, s.BlockFixture)
        x, y, z = f.size
        geoms = [GeomSpec("box", (x / 2, y / 2, z / 2), rgba, pos=(0.0, 0.0, z / 2))]
    yaw = math.radians(f.yaw_deg)
    quat = (math.cos(yaw / 2), 0.0, 0.0, math.sin(yaw / 2))
    spec = FixtureSpec(f.name, tuple(geoms), pos=(f.centre[0], f.centre[1], 0.0), quat=quat)
    if f.texture is not None:
        assets, material, _ = texture_assets(f.name, f.texture, f.colour, kind="2d")
        white = (1.0, 1.0, 1.0, 1.0)
        geoms = [GeomSpec(g.type, g.size, white, g.pos, g.quat, g.collide, material=material) for g in geoms]
        spec = FixtureSpec(f.name, tuple(geoms), pos=spec.pos, quat=quat, assets=assets)
    return spec
