"""Checks of a task file that need the whole file: names that must exist, goals the simulator can reach,
containers that must hold their content, objects a gripper can hold, a layout that must fit the table.

Each problem is one :class:`Problem` (the field's path and what is wrong, with what is allowed), so
``pilworld task check`` prints one line per problem and every other command the first one.
"""

from __future__ import annotations

from dataclasses import dataclass

from simrig.tasks import schema as s
from simrig.tasks.base import sample_positions
from simrig.tasks.predicates import placement
from simrig.tasks.shapes import Geometry

# The simulated table (simrig.scene: centre x −0.05, half sizes 0.55 × 0.6) and the gripper's opening.
TABLE_X = (-0.6, 0.5)
TABLE_Y = (-0.6, 0.6)
MAX_GRASP_WIDTH = 0.075  # the fingers open 85 mm; leave room to close around an object
LAYOUT_SEEDS = 20  # a layout must be drawn for each of these seeds


@dataclass(frozen=True)
class Problem:
    field: str
    message: str


def _walk(goal: s.Predicate, path: str) -> list[tuple[s.Predicate, str]]:
    out = [(goal, path)]
    kind = goal.kind
    if kind in ("all", "any"):
        for k, child in enumerate(getattr(goal, kind)):
            out += _walk(child, f"{path}.{kind}.{k}")
    return out


def check_task(task: s.TaskFile, geometry: dict[str, Geometry]) -> list[Problem]:
    """Every cross-field problem of ``task`` (``geometry``: the built objects' shapes)."""
    problems: list[Problem] = []
    add = lambda field, msg: problems.append(Problem(field, msg))  # noqa: E731
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
            if sub.object is not None or sub.goal is not None:
                add(
                    f"subtasks.{k}",
                    "names an object or a goal but the task has no objects (a hardware-only task "
                    "describes subtasks with operator_setup and operator_success)",
                )
        if task.layout is not None:
            add("layout", "a task without objects has nothing to lay out; remove 'layout' or add objects")
        return problems
    _check_subtasks(task, objects, regions, geometry, add)
    _check_layout(task, objects, add)
    return problems


def _check_subtasks(
    task: s.TaskFile, objects: list[str], regions: list[str], geometry: dict[str, Geometry], add
) -> None:  # type: ignore[no-untyped-def]
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
            add(
                f"objects.{objects.index(sub.object)}",
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


def _check_predicate(  # type: ignore[no-untyped-def]
    pred: s.Predicate,
    path: str,
    subject: str,
    objects: list[str],
    regions: list[str],
    geometry: dict[str, Geometry],
    add,
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


def _check_layout(task: s.TaskFile, objects: list[str], add) -> None:  # type: ignore[no-untyped-def]
    layout = task.layout
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
    # Draw the scatter groups for a few seeds, as the simulator will: a layout that cannot fit is refused here.
    import numpy as np

    for seed in range(LAYOUT_SEEDS):
        rng = np.random.default_rng([seed, 0])
        done: list[tuple[float, float, float]] = []
        for g, group in enumerate(layout.scatter):
            keep = [(d.centre[0], d.centre[1], d.radius) for d in (*layout.keep_out, *group.keep_out)]
            keep += [(x, y, group.min_distance) for x, y, _ in done]
            try:
                pts = sample_positions(
                    rng,
                    len(group.objects),
                    x_range=group.x,
                    y_range=group.y,
                    min_distance=group.min_distance,
                    keep_out=tuple(keep),
                )
            except RuntimeError:
                area = (group.x[1] - group.x[0]) * (group.y[1] - group.y[0])
                add(
                    f"layout.scatter.{g}",
                    f"cannot place {len(group.objects)} objects {group.min_distance} m apart in "
                    f"x {list(group.x)}, y {list(group.y)} ({area:.3f} m², keep-out discs included): widen the area "
                    "or lower min_distance",
                )
                return
            done += [(x, y, 0.0) for x, y in pts]
