"""Checks of a task file that need the whole file: names that must exist, goals the simulator can reach,
containers that must hold their content, objects a gripper can hold, a layout that must fit the table.

Each problem is one :class:`Problem` (the field's path and what is wrong, with what is allowed), so
``pilworld task check`` prints one line per problem and every other command the first one.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

from simrig.tasks import schema as s
from simrig.tasks.base import LayoutError
from simrig.tasks.mesh import MeshError
from simrig.tasks.predicates import placement
from simrig.tasks.shapes import Geometry, build_object

# The simulated table (simrig.scene: centre x −0.05, half sizes 0.55 × 0.6) and the gripper's opening.
TABLE_X = (-0.6, 0.5)
TABLE_Y = (-0.6, 0.6)
MAX_GRASP_WIDTH = 0.075  # the fingers open 85 mm; leave room to close around an object
LAYOUT_SEEDS = 20  # a layout must be drawn for each of these seeds


@dataclass(frozen=True)
class Problem:
    field: str
    message: str


Add = Callable[[str, str], None]  # records one problem: (field, message)


def build_problems(task: s.TaskFile) -> list[Problem]:
    """Objects that cannot be built: a mesh that is unreadable, open, too large or too detailed; an image
    that cannot be read as a texture. One problem per object, naming the field that holds the file."""
    problems = []
    for k, obj in enumerate(task.objects):
        try:
            build_object(obj)
        except MeshError as exc:
            problems.append(Problem(f"objects.{k}.file", str(exc)))
        except ValueError as exc:
            field = "texture.image" if obj.texture is not None and obj.texture.image else ""
            problems.append(Problem(f"objects.{k}" + (f".{field}" if field else ""), str(exc)))
    return problems


def size_field(obj: s.ObjectDef) -> str:
    """The field that sets how wide ``obj`` is across (where a too-wide object is fixed)."""
    if isinstance(obj, s.BoxObject | s.OpenBoxObject):
        return "size"
    if isinstance(obj, s.BowlObject):
        return "top_radius"
    if isinstance(obj, s.CompoundObject):
        return f"parts.{obj.grasp_part}"
    if isinstance(obj, s.MeshObject):
        return "scale"
    return "radius"


def _walk(goal: s.Predicate, path: str) -> list[tuple[s.Predicate, str]]:
    out = [(goal, path)]
    kind = goal.kind
    if kind in ("all", "any"):
        for k, child in enumerate(getattr(goal, kind)):
            out += _walk(child, f"{path}.{kind}.{k}")
    return out


def check_task(
    task: s.TaskFile, geometry: dict[str, Geometry], draw: Callable[[int], object] | None = None
) -> list[Problem]:
    """Every cross-field problem of ``task`` (``geometry``: the built objects' shapes; ``draw(seed)``: the
    simulator's layout, tried for :data:`LAYOUT_SEEDS` seeds once everything else is valid)."""
    problems: list[Problem] = []

    def add(field: str, message: str) -> None:
        problems.append(Problem(field, message))

    objects = [o.name for o in task.objects]
    regions = [r.name for r in task.regions]
    fixtures = [f.name for f in task.fixtures]
    for what, names in (("objects", objects), ("regions", regions), ("fixtures", fixtures)):
        seen: set[str] = set()
        for k, name in enumerate(names):
            if name in seen:
                add(f"{what}.{k}.name", f"duplicate name {name!r}; names must be unique within {what}")
            seen.add(name)
    for k, name in enumerate(regions):
        if name in objects:
            add(f"regions.{k}.name", f"{name!r} is also an object's name; a region needs a name of its own")
    for k, r in enumerate(task.regions):
        if not (TABLE_X[0] <= r.centre[0] <= TABLE_X[1] and TABLE_Y[0] <= r.centre[1] <= TABLE_Y[1]):
            add(
                f"regions.{k}.centre", f"{list(r.centre)} is off the table (x in {list(TABLE_X)}, y in {list(TABLE_Y)})"
            )
    if not task.objects:
        for k, sub in enumerate(task.subtasks):
            for key in ("object", "goal"):
                if getattr(sub, key) is not None:
                    add(
                        f"subtasks.{k}.{key}",
                        f"a task without objects (hardware only) has no {key} to name; describe the subtask "
                        "with operator_setup and operator_success, or add the objects",
                    )
        if task.layout is not None:
            add("layout", "a task without objects has nothing to lay out; remove 'layout' or add objects")
        return problems
    _check_subtasks(task, objects, regions, geometry, add)
    _check_layout(task, objects, geometry, add, problems, draw if not problems else None)
    return problems


def _check_subtasks(
    task: s.TaskFile, objects: list[str], regions: list[str], geometry: dict[str, Geometry], add: Add
) -> None:
    for k, sub in enumerate(task.subtasks):
        where = f"subtasks.{k}"
        if sub.object is None:
            add(
                f"{where}.object", f"a simulated task's subtask names the object it moves (one of {', '.join(objects)})"
            )
            continue
        if sub.object not in objects:
            add(f"{where}.object", f"no object called {sub.object!r} (objects: {', '.join(objects)})")
            continue
        if sub.goal is None:
            add(f"{where}.goal", f"subtask {k} has no goal (a predicate: {', '.join(s.PREDICATES)})")
            continue
        g = geometry.get(sub.object)
        if g is not None and g.grasp.kind == "pinch" and g.grasp.width > MAX_GRASP_WIDTH:
            i = objects.index(sub.object)
            add(
                f"objects.{i}.{size_field(task.objects[i])}",
                f"{sub.object} is {g.grasp.width * 1000:.0f} mm across its "
                f"narrowest side; the gripper holds at most {MAX_GRASP_WIDTH * 1000:.0f} mm",
            )
        for pred, path in _walk(sub.goal, f"{where}.goal"):
            _check_predicate(pred, path, sub.object, objects, regions, geometry, add)
        if placement(sub.goal, sub.object) is None and k < len(task.subtasks) - 1:
            add(
                f"{where}.goal",
                "needs an in_region, on or inside about its object: later subtasks start with it "
                "done, so the simulator must know where it ends up",
            )


def _check_predicate(
    pred: s.Predicate,
    path: str,
    subject: str,
    objects: list[str],
    regions: list[str],
    geometry: dict[str, Geometry],
    add: Add,
) -> None:
    kind = pred.kind
    if kind in ("all", "any"):
        return
    body = getattr(pred, kind)
    name = body.object or subject
    if body.object is not None and body.object not in objects:
        add(f"{path}.{kind}.object", f"no object called {body.object!r} (objects: {', '.join(objects)})")
        return
    if kind == "in_region" and body.region not in regions:
        add(f"{path}.in_region.region", f"no region called {body.region!r} (regions: {', '.join(regions) or 'none'})")
    if kind == "on":
        if body.support not in objects:
            add(f"{path}.on.support", f"no object called {body.support!r} (objects: {', '.join(objects)})")
        elif body.support == name:
            add(f"{path}.on.support", f"{name} cannot rest on itself")
    if kind == "inside":
        if body.container not in objects:
            add(f"{path}.inside.container", f"no object called {body.container!r} (objects: {', '.join(objects)})")
            return
        if body.container == name:
            add(f"{path}.inside.container", f"{name} cannot be inside itself")
            return
        box = geometry.get(body.container)
        content = geometry.get(name)
        if box is None or content is None:
            return
        if box.container is None:
            add(f"{path}.inside.container", f"{body.container} is not a container (bowl, cup or open_box)")
            return
        seat = box.container.seat(content.base_radius)
        if content.radius > box.container.opening or seat == float("inf"):
            add(
                f"{path}.inside.container",
                f"{body.container} is too small for {name}: its opening is "
                f"{box.container.opening * 1000:.0f} mm in radius, {name} is {content.radius * 1000:.0f} mm",
            )


def _check_layout(
    task: s.TaskFile,
    objects: list[str],
    geometry: dict[str, Geometry],
    add: Add,
    problems: list[Problem],
    draw: Callable[[int], object] | None,
) -> None:
    layout = task.layout
    problems_before = len(problems)
    if layout is None:
        add("layout", "a task with objects needs a layout (scatter groups) to place them")
        return
    placed: list[str] = []
    for g, group in enumerate(layout.scatter):
        for k, name in enumerate(group.objects):
            if name not in objects:
                add(f"layout.scatter.{g}.objects.{k}", f"no object called {name!r} (objects: {', '.join(objects)})")
            elif name in placed:
                add(f"layout.scatter.{g}.objects.{k}", f"{name} is placed twice")
            placed.append(name)
        for axis, rng, table in (("x", group.x, TABLE_X), ("y", group.y, TABLE_Y)):
            if rng[0] < table[0] or rng[1] > table[1]:
                add(f"layout.scatter.{g}.{axis}", f"{list(rng)} reaches off the table ({axis} in {list(table)})")
    for k, st in enumerate(layout.stacked):
        target = st.on if st.on is not None else st.inside
        if st.inside is not None and st.inside in geometry and geometry[st.inside].container is None:
            add(f"layout.stacked.{k}.inside", f"{st.inside} is not a container (bowl, cup or open_box)")
        if st.object not in objects:
            add(f"layout.stacked.{k}.object", f"no object called {st.object!r} (objects: {', '.join(objects)})")
        elif st.object in placed:
            add(f"layout.stacked.{k}.object", f"{st.object} is placed twice")
        if target not in placed:
            add(
                f"layout.stacked.{k}",
                f"{target!r} must be placed (scattered or stacked) before {st.object} starts on it",
            )
        placed.append(st.object)
    missing = [n for n in objects if n not in placed]
    if missing:
        add("layout", f"{', '.join(missing)} placed by no scatter group or stacked entry")
    if draw is None or problems_before != len(problems):
        return
    # Lay the task out for a few seeds, exactly as the simulator will: a layout that cannot fit is refused here.
    for seed in range(LAYOUT_SEEDS):
        try:
            draw(seed)
        except LayoutError as exc:
            group = layout.scatter[exc.group]
            area = (group.x[1] - group.x[0]) * (group.y[1] - group.y[0])
            add(
                f"layout.scatter.{exc.group}",
                f"cannot place {len(group.objects)} objects {group.min_distance} m apart in "
                f"x {list(group.x)}, y {list(group.y)} ({area:.3f} m², keep-out discs and earlier groups "
                f"included; seed {seed}): widen the area or lower min_distance",
            )
            return
