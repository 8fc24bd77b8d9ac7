"""What the scripted policies know about each task, and how they read the task's state from an image.

This is the policy's *prior*: object colours and sizes, where the slots and the stacking mark are,
and how the paper's instruction maps to a task. It is what a trained VLA has learned; it is not
simulator state. Each call sees only the head-camera image: every object is found by colour,
back-projected through the rig's ``CameraModel`` onto the plane where it would sit, and the task's
progress is inferred from those positions (which cube already sits in its slot, which block is
already on the tower).
"""

from __future__ import annotations

import math
from abc import ABC, abstractmethod
from collections.abc import Mapping
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from calib.camera_model import CameraModel
from hw_drivers.sim.tasks import sort_cubes as sc
from hw_drivers.sim.tasks import stack_blocks as sb
from hw_drivers.sim.tasks import stack_bowls as sw
from pilworld.perception.colour import Blob, ColourClass, largest_blob, segment

GRASP_Z = 0.022  # TCP height for grasping a cube or block resting on the table [m]
FULL_BLOCK_PX = 25  # a block's blob in the 128×128 head view when mostly visible (~35–55 px measured)
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


class TaskKnowledge(ABC):
    """One task as a policy understands it."""

    instruction: str
    classes: list[ColourClass]

    @abstractmethod
    def progress(self, seen: Sightings, camera: CameraModel) -> list[tuple[str, Intent | None, bool]]:
        """Per object in task order: (name, its pick-and-place if it can be planned, whether it looks done)."""

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


def _rgb(rgba: tuple[float, ...]) -> tuple[float, float, float]:
    return (rgba[0], rgba[1], rgba[2])


class SortCubesKnowledge(TaskKnowledge):
    instruction = sc.SortCubes.instruction

    def __init__(self) -> None:
        self.classes = [ColourClass(n, _rgb(rgba)) for n, _, rgba, _ in sc.CUBES]

    def progress(self, seen: Sightings, camera: CameraModel) -> list[tuple[str, Intent | None, bool]]:
        out: list[tuple[str, Intent | None, bool]] = []
        for k, (name, edge, _, _) in enumerate(sc.CUBES):
            uv = seen.uv.get(name)
            slot = (sc.SLOT_X, sc.SLOT_YS[k])
            if uv is None:
                out.append((name, None, False))  # never seen: cannot act on it
                continue
            xy = _bp(camera, uv, edge / 2)
            intent = Intent(name, (float(xy[0]), float(xy[1]), GRASP_Z), slot, GRASP_Z + 0.008)
            out.append((name, intent, _near(xy, slot, 0.025)))
        return out


class StackBlocksKnowledge(TaskKnowledge):
    instruction = sb.StackBlocks.instruction

    def __init__(self) -> None:
        self.classes = [ColourClass(n, _rgb(rgba)) for n, rgba in sb.BLOCKS]

    def progress(self, seen: Sightings, camera: CameraModel) -> list[tuple[str, Intent | None, bool]]:
        """The tower grows from the first block; a block is on it if, seen at that level, it sits above it.

        From above, a stacked block hides most of the one below, so the base's own sighting is trusted
        only while mostly visible; otherwise the block seen at the next level marks the tower.
        """
        names = [n for n, _ in sb.BLOCKS]
        e = sb.BLOCK
        base = names[0]
        # The base's own estimate is trusted only from a mostly visible blob: under a stacked block
        # (seen from above) only a sliver of it shows, whose centroid is centimetres off.
        tower: XY | None = None
        loose: XY | None = None  # an untrusted estimate, good enough to tell "near" from "elsewhere"
        if base in seen.uv:
            loose = _bp(camera, seen.uv[base], e / 2)
            if seen.count.get(base, 0) >= FULL_BLOCK_PX * seen.scale**2:
                tower = loose
        out: list[tuple[str, Intent | None, bool]] = []
        stacked = True
        for level, name in enumerate(names[1:], start=1):
            if name not in seen.uv:
                out.append((name, None, False))
                stacked = False
                continue
            on_tower = _bp(camera, seen.uv[name], e / 2 + level * e)
            if tower is not None:
                done = stacked and _near(on_tower, tower, 0.025)
            elif loose is not None:  # the level below shows a sliver: this block sits on it if near it
                done = stacked and _near(on_tower, loose, 0.045)
            else:  # the base was never seen at all: only a block standing on it hides it completely
                done = stacked and level == 1
            intent = None
            goal_xy = tower if tower is not None else loose
            if goal_xy is not None:
                xy = _bp(camera, seen.uv[name], e / 2)
                goal = (float(goal_xy[0]), float(goal_xy[1]))
                intent = Intent(name, (float(xy[0]), float(xy[1]), GRASP_Z), goal, GRASP_Z + level * e + 0.006)
            out.append((name, intent, done))
            if done:
                tower = loose = on_tower
            else:
                stacked = False
        return out


class StackBowlsKnowledge(TaskKnowledge):
    instruction = sw.StackBowls.instruction

    def __init__(self) -> None:
        self.classes = [ColourClass(n, _rgb(rgba)) for n, _, _, _, rgba, _ in sw.BOWLS]

    @staticmethod
    def grasp_height(index: int) -> float:
        """TCP height above the bowl's underside for pinching the lip (fingertips just above its bottom)."""
        _, _, _, h, _, _ = sw.BOWLS[index]
        return h - sw.LIP + sw.WALL / 2 + 0.004 + 0.018  # 0.018: fingertips below the TCP

    @staticmethod
    def rim_radius(index: int) -> float:
        return sw.BOWLS[index][2]  # the lip stands at the top radius

    def progress(self, seen: Sightings, camera: CameraModel) -> list[tuple[str, Intent | None, bool]]:
        """Bowls go onto the fixed stacking mark, so each is judged against the mark itself.

        A bowl nested at the mark implies every bigger bowl is under it: that catches the large bowl
        whose visible ring, half hidden by a gripper, would otherwise look off the mark.
        """
        mark = np.asarray(sw.STACK_XY, dtype=np.float64)
        nested: list[XY | None] = []
        for k, (name, _, _, h, _, _) in enumerate(sw.BOWLS):
            uv = seen.uv.get(name)
            nested.append(None if uv is None else _bp(camera, uv, sw.nested_base_height(k) + h / 2))
        at_mark = [p is not None and _near(p, mark, 0.025) for p in nested]
        out: list[tuple[str, Intent | None, bool]] = []
        stacked = True
        target: XY | None = mark
        for k, (name, _, _, h, _, _) in enumerate(sw.BOWLS):
            done = stacked and any(at_mark[k:])
            uv = seen.uv.get(name)
            intent = None
            if uv is not None and target is not None:
                xy = _bp(camera, uv, h / 2)
                goal = (float(target[0]), float(target[1]))
                intent = Intent(name, (float(xy[0]), float(xy[1]), self.grasp_height(k)), goal, 0.0)
            out.append((name, intent, done))
            stacked = done
            # The next bowl goes into this one: aim at where it is seen, else at the mark.
            here = nested[k]
            target = (here if here is not None and at_mark[k] else mark) if done else None
        return out

    def rim_grasp(
        self, index: int, centre: XY, towards: XY
    ) -> tuple[tuple[float, float, float], float, tuple[float, float]]:
        """Grasp point on the rim facing ``towards`` (the arm), the yaw and the held centre offset."""
        d = np.asarray(towards, dtype=np.float64) - centre
        d /= max(float(np.linalg.norm(d)), 1e-9)
        r = self.rim_radius(index)
        p = centre + r * d
        yaw = math.atan2(float(d[0]), float(-d[1]))  # tool y (closing axis) along the radius
        return (float(p[0]), float(p[1]), self.grasp_height(index)), yaw, (float(-r * d[0]), float(-r * d[1]))


KNOWLEDGE: Mapping[str, type[TaskKnowledge]] = {
    sc.SortCubes.name: SortCubesKnowledge,
    sw.StackBowls.name: StackBowlsKnowledge,
    sb.StackBlocks.name: StackBlocksKnowledge,
}


def knowledge_for_instruction(instruction: str) -> TaskKnowledge:
    """The task whose instruction this is (case and surrounding space ignored)."""
    want = instruction.strip().lower()
    for cls in KNOWLEDGE.values():
        if cls.instruction.strip().lower() == want:
            return cls()
    known = "; ".join(repr(c.instruction) for c in KNOWLEDGE.values())
    raise ValueError(f"instruction: the scripted policies know {known}; got {instruction!r}")
