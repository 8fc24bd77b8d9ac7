"""Injected hallucinations: faulted copies of clean episodes, to measure the hallucination detector.

Each fault takes a clean episode and a frame ``k`` and returns a copy that shows one of the paper's
hallucination categories (appendix "Hallucination-free ratio") from frame ``k`` on; frames before
``k``, the state and the actions are untouched, so a detector must find the fault in the images:

* :func:`delete_object` — *object disappearing*: from ``k`` on, the object's pixels are painted with
  the local table colour in every view where its colour is seen.
* :func:`duplicate_object` — *object appearing*: from ``k`` on, the head view shows a copy of the
  object (its frame-``k`` patch) on a free part of the table, behind anything that later passes over
  that spot.
* :func:`swap_views` — *cross-view conflict*: from ``k`` on, ``cam_high`` and a wrist view exchange
  their frames.
* :func:`teleport_arm` — *discontinuous arm motion*: from ``k`` on, every view shows the frame ``s``
  steps later (the last frame repeats at the end) while the state stays. The rendered arm jumps to
  where it would be ``s`` frames later and then keeps moving, but the state — the measured joints in
  the real branch, the command in the imagined one — goes on smoothly: exactly what a world model
  that skips ahead does. ``s`` is the smallest shift that moves a gripper's projected TCP by at least
  ``min_jump_px`` in the head view (20 px at 128², ~1/6 of the image), so a jump is always visible.
  Shifting the state instead (images untouched) would put the discontinuity into the commanded
  trajectory, which in the imagined branch is the policy's output, not the world model's.

Objects are told apart by colour, found in the episode's own head view
(:func:`pilworld.perception.objects.discover_colours_over`), so an episode of any task can be faulted.

A fault that cannot be applied at ``k`` (no object visible at ``k - 1``, no free table spot, the arms
never move far enough after ``k``) raises :class:`FaultError`; :func:`inject` draws the object and
the spot with a seeded generator and is what the benchmark and the tests call.
"""

from __future__ import annotations

import dataclasses

import cv2
import numpy as np
from numpy.typing import NDArray

from pilworld.config.rig import RigConfig
from pilworld.data.episode import Episode
from pilworld.judges.base import episode_task
from pilworld.judges.hallucination_scene import (
    REFERENCE_WIDTH,
    dilate,
    learn_table,
    table_mask,
    without_table_texture,
)
from pilworld.perception.colour import ColourClass, segment
from pilworld.perception.objects import discover_colours_over
from pilworld.types import HEAD_VIEW

FAULTS: tuple[str, ...] = ("delete_object", "duplicate_object", "swap_views", "teleport_arm")
MIN_VISIBLE_PX = 10  # an object's largest blob must show this many head-view pixels at k-1 to be faulted (at 128²)


class FaultError(ValueError):
    """The fault cannot be applied to this episode at this frame."""


def _check_k(ep: Episode, k: int) -> None:
    if isinstance(k, bool) or not isinstance(k, int | np.integer) or not 1 <= k < ep.length:
        raise ValueError(f"k: expected a frame in 1..{ep.length - 1}, got {k!r}")


def _scale(ep: Episode) -> float:
    return float(ep.images[HEAD_VIEW].shape[2]) / REFERENCE_WIDTH


def object_colours(ep: Episode) -> list[ColourClass]:
    """The episode's object colours, found in its head view (no task knowledge: any task can be faulted).

    A colour the start frames show only as faint specks over the table is its texture (a warm wood's grain), not an
    object, and is left out (:func:`~pilworld.judges.hallucination_scene.table_texture`): painting grains away is
    no object deleted. No arms are drawn here (the faults need no rig); arm pixels pass no colour test anyway.
    """
    head = ep.images[HEAD_VIEW]
    no_arms = np.zeros(head.shape[:3], np.uint8)
    classes = without_table_texture(head, discover_colours_over(head), no_arms, scale=_scale(ep))
    if not classes:
        raise FaultError(f"task {episode_task(ep)!r} ({ep.task!r}): no coloured object visible in {HEAD_VIEW}")
    return classes


def _class(classes: list[ColourClass], name: str) -> ColourClass:
    for c in classes:
        if c.name == name:
            return c
    raise ValueError(f"colour: expected one of {[c.name for c in classes]}, got {name!r}")


def _with(ep: Episode, images: dict[str, NDArray[np.uint8]], fault: dict[str, object]) -> Episode:
    return dataclasses.replace(ep, images=images, extra={**ep.extra, "fault": fault})


def visible_objects(ep: Episode, frame: int) -> dict[str, int]:
    """Head-view pixels of each object colour's largest blob at ``frame`` (below MIN_VISIBLE_PX left out).

    The largest blob, not all the colour's pixels: an object shows as one blob, and a colour's scattered specks
    (a table grain of its hue, a one-pixel seam) add up to no object to fault."""
    classes = object_colours(ep)
    masks = segment(ep.images[HEAD_VIEW][frame], classes)
    need = MIN_VISIBLE_PX * _scale(ep) ** 2
    out: dict[str, int] = {}
    for c in classes:
        n, _, stats, _ = cv2.connectedComponentsWithStats(masks[c.name].astype(np.uint8), connectivity=8)
        largest = int(stats[1:, cv2.CC_STAT_AREA].max()) if n > 1 else 0
        if largest >= need:
            out[c.name] = largest
    return out


def _object_region(mask: NDArray[np.bool_], grow: int) -> NDArray[np.bool_]:
    """An object's colour mask with holes (dark inner faces) closed and anti-aliased edges added."""
    kernel = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (5, 5))
    closed = np.asarray(cv2.morphologyEx(mask.astype(np.uint8), cv2.MORPH_CLOSE, kernel), dtype=np.uint8)
    return dilate(closed, grow)


def _local_table_colour(
    frame: NDArray[np.uint8], region: NDArray[np.bool_], table: NDArray[np.bool_]
) -> NDArray[np.uint8]:
    source = frame.reshape(-1, 3)  # last resort: the whole frame
    for ring in (4, 8, 16, 32):
        near = dilate(region, ring) & ~region & table
        if near.sum() >= 8:
            source = frame[near]
            break
    else:
        if table.any():
            source = frame[table]
    colour: NDArray[np.uint8] = np.median(source, axis=0).astype(np.uint8)
    return colour


def delete_object(ep: Episode, k: int, colour: str | None = None) -> Episode:
    """From frame ``k`` on, paint object ``colour`` (a class name, default the largest at ``k - 1``) away."""
    _check_k(ep, k)
    classes = object_colours(ep)
    if colour is None:
        seen = visible_objects(ep, k - 1)
        if not seen:
            raise FaultError(f"no object visible in {HEAD_VIEW} at frame {k - 1}")
        colour = max(seen, key=lambda n: seen[n])
    cls = _class(classes, colour)
    grow = max(1, round(2 * _scale(ep)))
    images: dict[str, NDArray[np.uint8]] = {}
    for view, frames in ep.images.items():
        out = frames.copy()
        for t in range(k, ep.length):
            frame = out[t]
            masks = segment(frame, classes)
            if not masks[cls.name].any():
                continue
            region = _object_region(masks[cls.name], grow)
            objects = np.zeros(region.shape, bool)
            for c in classes:
                objects |= masks[c.name]
            table = table_mask(frame, learn_table(frame, dilate(objects, 1)))
            frame[region] = _local_table_colour(frame, region, table & ~objects)
        images[view] = out
    return _with(ep, images, {"type": "delete_object", "k": int(k), "object": cls.name})


def duplicate_object(
    ep: Episode, k: int, colour: str | None = None, *, rng: np.random.Generator | None = None
) -> Episode:
    """From frame ``k`` on, show a second ``colour`` object (default the largest at ``k``) on free table."""
    _check_k(ep, k)
    classes = object_colours(ep)
    rng = rng or np.random.default_rng(0)
    head = ep.images[HEAD_VIEW]
    T, H, W, _ = head.shape
    s = _scale(ep)
    if colour is None:
        seen = visible_objects(ep, k)
        if not seen:
            raise FaultError(f"no object visible in {HEAD_VIEW} at frame {k}")
        colour = max(seen, key=lambda n: seen[n])
    cls = _class(classes, colour)
    masks = segment(head[k], classes)
    n, lab, stats, _ = cv2.connectedComponentsWithStats(masks[cls.name].astype(np.uint8), connectivity=8)
    if n < 2 or stats[1:, cv2.CC_STAT_AREA].max() < MIN_VISIBLE_PX * s * s:
        raise FaultError(f"{cls.name} is not visible in {HEAD_VIEW} at frame {k}")
    main = lab == 1 + int(np.argmax(stats[1:, cv2.CC_STAT_AREA]))
    patch = _object_region(main, max(1, round(s)))
    vs, us = np.nonzero(patch)
    # Free table: table-coloured in k-1..k+1 around the copy, and well away from every object.
    objects = np.zeros((H, W), bool)
    for c in classes:
        objects |= masks[c.name]
    free = np.ones((H, W), bool)
    table = learn_table(head[0], dilate(objects, 2))
    for t in range(max(0, k - 1), min(T, k + 2)):
        free &= table_mask(head[t], table)
    free &= ~dilate(objects, 14 * s)
    margin = round(4 * s)
    free[:1], free[-1:], free[:, :1], free[:, -1:] = False, False, False, False  # keep off the image border
    blocked = dilate(~free, margin).astype(np.uint8)  # the copy, grown by the margin, must lie on free table
    v0, u0 = int(vs.min()), int(us.min())
    kernel = patch[v0 : int(vs.max()) + 1, u0 : int(us.max()) + 1].astype(np.uint8)
    # dilate with anchor (0, 0): hit[a] = max over kernel pixels p of blocked[a + p]; outside counts as blocked.
    hit = cv2.dilate(blocked, kernel, anchor=(0, 0), borderType=cv2.BORDER_CONSTANT, borderValue=1)
    av, au = np.nonzero(hit == 0)
    if av.size == 0:
        raise FaultError(f"no free table spot for a copy of {cls.name} at frame {k}")
    pick = int(rng.integers(av.size))
    dv, du = int(av[pick]) - v0, int(au[pick]) - u0
    colours = head[k][vs, us]
    dest_v, dest_u = vs + dv, us + du
    background = head[k][dest_v, dest_u].astype(np.int16)
    out = head.copy()
    for t in range(k, T):
        # Composited behind anything that covers the spot later (an arm passing over it).
        same = np.abs(head[t][dest_v, dest_u].astype(np.int16) - background).max(axis=1) <= 30
        out[t][dest_v[same], dest_u[same]] = colours[same]
    images = {**ep.images, HEAD_VIEW: out}
    where = (float(us.mean() + du), float(vs.mean() + dv))
    return _with(ep, images, {"type": "duplicate_object", "k": int(k), "object": cls.name, "uv": where})


def swap_views(ep: Episode, k: int, wrist: str = "cam_left_wrist") -> Episode:
    """From frame ``k`` on, ``cam_high`` shows the frames of ``wrist`` and ``wrist`` those of ``cam_high``."""
    _check_k(ep, k)
    if wrist not in ep.images or wrist == HEAD_VIEW:
        raise ValueError(f"wrist: expected one of {sorted(v for v in ep.images if v != HEAD_VIEW)}, got {wrist!r}")
    head, other = ep.images[HEAD_VIEW].copy(), ep.images[wrist].copy()
    if head.shape != other.shape:
        raise FaultError(f"{HEAD_VIEW} and {wrist} differ in size: {head.shape} vs {other.shape}")
    head[k:], other[k:] = ep.images[wrist][k:], ep.images[HEAD_VIEW][k:]
    images = {**ep.images, HEAD_VIEW: head, wrist: other}
    return _with(ep, images, {"type": "swap_views", "k": int(k), "view": wrist})


def teleport_arm(ep: Episode, k: int, rig: RigConfig, *, min_jump_px: float = 20.0) -> Episode:
    """From frame ``k`` on, every view runs ``s`` frames ahead of the state (see the module docstring)."""
    _check_k(ep, k)
    cam = rig.head_camera_model
    uv, visible = cam.project(rig.kinematics.gripper_points(ep.state.astype(np.float64)))  # (T, 2, 2), (T, 2)
    need = min_jump_px * _scale(ep)
    shift = 0
    for s in range(1, ep.length - k):
        jump = np.hypot(*(uv[k + s] - uv[k]).T)  # per arm
        if bool(np.any((jump >= need) & visible[k] & visible[k + s])):
            shift = s
            break
    if shift == 0:
        raise FaultError(f"no gripper moves {need:.0f} px in {HEAD_VIEW} after frame {k}")
    src = np.minimum(np.arange(ep.length) + shift, ep.length - 1)
    src[:k] = np.arange(k)
    images = {v: f[src] for v, f in ep.images.items()}
    return _with(ep, images, {"type": "teleport_arm", "k": int(k), "shift": int(shift)})


def inject(fault: str, ep: Episode, k: int, rig: RigConfig, rng: np.random.Generator) -> Episode:
    """Apply ``fault`` (one of :data:`FAULTS`) at ``k``, drawing its free choices from ``rng``.

    The object to delete or copy is drawn among those visible in the head view at ``k - 1`` and at ``k``: the
    fault's first frame must show what it changes (an object an arm hides at ``k`` would vanish unseen, the
    first sign of it frames later, when the arm has moved on); the wrist view to swap with, among the wrist
    views.
    """
    if fault in ("delete_object", "duplicate_object"):
        now = visible_objects(ep, k)
        seen = [n for n in sorted(visible_objects(ep, k - 1)) if n in now]
        if not seen:
            raise FaultError(f"no object visible in {HEAD_VIEW} at frames {k - 1} and {k}")
        colour = seen[int(rng.integers(len(seen)))]
        if fault == "delete_object":
            return delete_object(ep, k, colour)
        return duplicate_object(ep, k, colour, rng=rng)
    if fault == "swap_views":
        wrists = sorted(v for v in ep.images if v != HEAD_VIEW)
        return swap_views(ep, k, wrists[int(rng.integers(len(wrists)))])
    if fault == "teleport_arm":
        return teleport_arm(ep, k, rig)
    raise ValueError(f"fault: expected one of {list(FAULTS)}, got {fault!r}")
