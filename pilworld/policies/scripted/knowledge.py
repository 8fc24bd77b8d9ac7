"""What a scripted policy knows about its task, read from the task file, and how it reads progress from an image.

This is the policy's *prior*, what a trained VLA has learned from its task: the objects' colours and shapes,
where each subtask's goal puts its object (a region, on a support, inside a container) and at what height.
It is not simulator state. Each call sees only the head-camera image: every object is found by colour,
back-projected through the rig's ``CameraModel`` onto the plane where it would sit, and the task's progress
is inferred from those positions.

Subtasks form *chains*: a subtask whose goal puts its object on or inside the object of an earlier subtask
continues that one's chain. A chain is rooted at a region (the slots, the stacking mark: each member is
judged against the region, and a member seen in place implies every one below it) or at an object no
subtask moves (the first block of a tower: judged against where that object is seen, trusted only while it
is mostly visible, since what is stacked on it hides it from above).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from calib.camera_model import CameraModel
from pilworld.perception.colour import Blob, ColourClass, largest_blob, segment
from simrig.tasks import Task, load_task
from simrig.tasks.shapes import Geometry

FULL_BLOCK_PX = 25  # a 4 cm block's blob in the 128×128 head view when mostly visible (~35–55 px measured)
FULL_BLOCK_RADIUS = 0.02 * math.sqrt(2)  # that block's horizontal radius [m]; other objects scale by area
DONE_TOL = 0.025  # a member seen this close to its chain's target counts as done [m]
LOOSE_TOL = 0.045  # … when the target object shows only a sliver
# Release heights above the goal's rest height + grasp height, by goal kind (set down, not dropped).
RELEASE_MARGIN = {"region": 0.008, "on": 0.006, "inside": 0.01}
XY = NDArray[np.float64]


@dataclass(frozen=True)
class Intent:
    """The next pick-and-place: which object, the TCP grasp point, and the object's goal centre."""

    obj: str
    grasp_xyz: tuple[float, float, float]
    goal_xy: tuple[float, float]  # where the object's centre must end up
    release_z: float  # TCP height at release [m] (bowls: recomputed from the rim grasp)


class Sightings:
    """Blob centroids of each object, remembered across calls while an object is occluded.

    Objects vanish under a gripper seen from above. A sighting near a gripper (in the image) replaces
    the remembered one only when it shows at least ``keep`` of the object's usual blob, so a gripper
    passing over an object does not drag its estimate; a sighting away from the grippers is always
    taken (the object may have moved, or look smaller elsewhere on the table), and so is one far from
    where the object was remembered (it was carried there).
    """

    def __init__(self, keep: float = 0.75, clear_px: float = 14.0, image_width: int = 128) -> None:
        self.keep = keep
        # Pixel thresholds are tuned at 128×128 and scale with the image (lengths by width, areas by its square).
        self.scale = image_width / 128.0
        self.clear_px = clear_px * self.scale
        self.uv: dict[str, XY] = {}
        self.count: dict[str, int] = {}  # pixels of the blob each remembered centroid came from
        self.best: dict[str, int] = {}
        self.last: dict[str, Blob | None] = {}

    def update(self, image: NDArray[np.uint8], classes: list[ColourClass], grippers_uv: NDArray[np.float64]) -> None:
        masks = segment(image, classes)
        for c in classes:
            blob = largest_blob(masks[c.name], min_pixels=3)
            self.last[c.name] = blob
            if blob is None:
                continue
            centre = np.asarray(blob.centroid_uv, dtype=np.float64)
            gaps = np.hypot(*(grippers_uv - centre).T) if len(grippers_uv) else np.array([np.inf])
            known = self.uv.get(c.name)
            moved = known is None or float(np.hypot(*(centre - known))) > self.clear_px
            if float(np.min(gaps)) > self.clear_px or moved:
                self.best[c.name] = blob.n_pixels
            elif blob.n_pixels >= self.keep * self.best.get(c.name, 0):
                self.best[c.name] = max(self.best.get(c.name, 0), blob.n_pixels)
            else:
                continue
            self.uv[c.name] = centre
            self.count[c.name] = blob.n_pixels


def _bp(camera: CameraModel, uv: XY, z: float) -> XY:
    pts, ok = camera.backproject_to_plane(uv, z)
    return np.asarray(pts[:2], dtype=np.float64) if bool(ok) else np.full(2, np.nan)


def _near(a: XY, b: XY | tuple[float, float], tol: float) -> bool:
    return bool(np.all(np.isfinite(a))) and float(np.hypot(*(np.asarray(a) - np.asarray(b)))) < tol


@dataclass(frozen=True)
class Member:
    """One subtask as the policy plans it: its object, where the goal puts it, and at what height."""

    index: int
    obj: str
    kind: str  # region | on | inside
    target: str  # the region or the object it goes onto or into
    parent: int | None  # the earlier subtask whose object is the target (same chain), or None
    rest: float  # underside height once done [m]
    geometry: Geometry


class TaskKnowledge:
    """One task file as a policy understands it."""

    def __init__(self, task: Task) -> None:
        self.task = task
        self.instruction = task.instruction
        self.classes = [ColourClass(n, task.colour(n)) for n in task.object_names]
        heights = self.heights = task.done_heights()  # each object's underside once its subtask is done
        moved = {task.subtask_object(k): k for k in range(task.num_subtasks)}
        self.members: list[Member] = []
        for k in range(task.num_subtasks):
            where = task.goal_placement(k)
            if where is None:
                continue
            obj = task.subtask_object(k)
            parent = moved.get(where.target) if where.kind != "region" else None
            if parent is not None and parent >= k:
                parent = None
            self.members.append(Member(k, obj, where.kind, where.target, parent, heights[obj], task.geometry[obj]))

    def geometry(self, obj: str) -> Geometry:
        return self.task.geometry[obj]

    def target_top(self, m: Member) -> float:
        """Height of the top of the object ``m`` goes onto or into, once that one is done [m]."""
        return self.heights[m.target] + self.geometry(m.target).height

    def member(self, obj: str) -> Member | None:
        return next((m for m in self.members if m.obj == obj), None)

    def _root(self, m: Member) -> Member:
        while m.parent is not None:
            m = next(p for p in self.members if p.index == m.parent)
        return m

    def progress(self, seen: Sightings, camera: CameraModel) -> list[tuple[str, Intent | None, bool]]:
        """Per subtask in order: (object, its pick-and-place if it can be planned, whether it looks done)."""
        chains: dict[int, list[Member]] = {}
        for m in self.members:
            chains.setdefault(self._root(m).index, []).append(m)
        verdict: dict[int, tuple[str, Intent | None, bool]] = {}
        for chain in chains.values():
            root = chain[0]
            if root.kind == "region":
                verdict.update(self._region_chain(chain, seen, camera))
            else:
                verdict.update(self._object_chain(chain, seen, camera))
        return [verdict[m.index] for m in self.members]

    def _resting_xy(self, m: Member, seen: Sightings, camera: CameraModel) -> XY | None:
        uv = seen.uv.get(m.obj)
        g = m.geometry
        return None if uv is None else _bp(camera, uv, g.bottom + g.mid)

    def _intent(self, m: Member, xy: XY, goal: XY | tuple[float, float]) -> Intent:
        g = m.geometry
        release = m.rest + g.grasp.height + RELEASE_MARGIN[m.kind] if g.grasp.kind == "pinch" else 0.0
        grasp = (float(xy[0]), float(xy[1]), g.grasp.height)
        return Intent(m.obj, grasp, (float(goal[0]), float(goal[1])), release)

    def _region_chain(
        self, chain: list[Member], seen: Sightings, camera: CameraModel
    ) -> dict[int, tuple[str, Intent | None, bool]]:
        """Members judged against the region: one seen in place implies every one below it."""
        region = self.task.regions[chain[0].target]
        mark = np.asarray(region.centre, dtype=np.float64)
        placed: list[XY | None] = []
        for m in chain:
            uv = seen.uv.get(m.obj)
            placed.append(None if uv is None else _bp(camera, uv, m.rest + m.geometry.bottom + m.geometry.mid))
        at_mark = [p is not None and _near(p, mark, DONE_TOL) for p in placed]
        out: dict[int, tuple[str, Intent | None, bool]] = {}
        stacked = True
        target: XY | None = mark
        for i, m in enumerate(chain):
            done = stacked and any(at_mark[i:])
            xy = self._resting_xy(m, seen, camera)
            intent = None if xy is None or target is None else self._intent(m, xy, target)
            out[m.index] = (m.obj, intent, done)
            stacked = done
            # The next member goes onto or into this one: aim at where it is seen, else at the region.
            here = placed[i]
            target = (here if here is not None and at_mark[i] else mark) if done else None
        return out

    def _object_chain(
        self, chain: list[Member], seen: Sightings, camera: CameraModel
    ) -> dict[int, tuple[str, Intent | None, bool]]:
        """A tower on an object no subtask moves; its own sighting is trusted only while mostly visible."""
        base = chain[0].target
        bgeo = self.task.geometry[base]
        tower: XY | None = None
        loose: XY | None = None  # an untrusted estimate, good enough to tell "near" from "elsewhere"
        if base in seen.uv:
            loose = _bp(camera, seen.uv[base], bgeo.bottom + bgeo.mid)
            full = FULL_BLOCK_PX * (bgeo.radius / FULL_BLOCK_RADIUS) ** 2
            if seen.count.get(base, 0) >= full * seen.scale**2:
                tower = loose
        out: dict[int, tuple[str, Intent | None, bool]] = {}
        stacked = True
        for level, m in enumerate(chain, start=1):
            if m.obj not in seen.uv:
                out[m.index] = (m.obj, None, False)
                stacked = False
                continue
            g = m.geometry
            on_tower = _bp(camera, seen.uv[m.obj], m.rest + g.bottom + g.mid)
            if tower is not None:
                done = stacked and _near(on_tower, tower, DONE_TOL)
            elif loose is not None:  # the level below shows a sliver: this one sits on it if near it
                done = stacked and _near(on_tower, loose, LOOSE_TOL)
            else:  # the base was never seen at all: only something standing on it hides it completely
                done = stacked and level == 1
            goal_xy = tower if tower is not None else loose
            intent = None
            if goal_xy is not None:
                xy = self._resting_xy(m, seen, camera)
                assert xy is not None
                intent = self._intent(m, xy, goal_xy)
            out[m.index] = (m.obj, intent, done)
            if done:
                tower = loose = on_tower
            else:
                stacked = False
        return out

    def intent_for(self, obj: str, seen: Sightings, camera: CameraModel) -> Intent | None:
        """The pick-and-place of ``obj`` (e.g. the object in the hand), done or not."""
        for name, intent, _ in self.progress(seen, camera):
            if name == obj:
                return intent
        return None

    def held_xy(self, seen: Sightings, camera: CameraModel, obj: str, z: float) -> XY | None:
        """Where the held object ``obj`` appears, back-projected at height ``z`` (None if unseen)."""
        blob = seen.last.get(obj)
        if blob is None:
            return None
        return _bp(camera, np.asarray(blob.centroid_uv), z)

    def rim_grasp(
        self, obj: str, centre: XY, towards: XY
    ) -> tuple[tuple[float, float, float], float, tuple[float, float]]:
        """Grasp point on a container's rim facing ``towards`` (the arm), the yaw and the held centre offset."""
        g = self.geometry(obj).grasp
        d = np.asarray(towards, dtype=np.float64) - centre
        d /= max(float(np.linalg.norm(d)), 1e-9)
        r = g.radius
        p = centre + r * d
        yaw = math.atan2(float(d[0]), float(-d[1]))  # tool y (closing axis) along the radius
        return (float(p[0]), float(p[1]), g.height), yaw, (float(-r * d[0]), float(-r * d[1]))


def knowledge_for(task: Task | str | Path) -> TaskKnowledge:
    """The knowledge of a task (a loaded task, a packaged task's name or a task file's path)."""
    return TaskKnowledge(load_task(task))


def knowledge_for_instruction(instruction: str) -> TaskKnowledge:
    """The packaged task whose instruction this is (case and surrounding space ignored)."""
    from simrig.tasks import PAPER_TASKS, packaged_tasks

    want = instruction.strip().lower()
    # The paper's tasks first: loading every packaged file (meshes, textures) on a policy's first call
    # would delay its first chunk.
    for name in (*PAPER_TASKS, *(n for n in packaged_tasks() if n not in PAPER_TASKS)):
        task = load_task(name)
        if task.instruction.strip().lower() == want:
            return TaskKnowledge(task)
    known = "; ".join(repr(load_task(n).instruction) for n in packaged_tasks())
    raise ValueError(f"instruction: the scripted policies know the packaged tasks {known}; got {instruction!r}")
