"""Render-and-compare: where a known primitive object sits, from its colour mask in one camera image.

Why not the blob centroid alone (:func:`pilworld.perception.colour.locate_on_plane`): the success checks
of the simulated tasks need the object's centre to within 1.5–3 cm of its goal, and the goal of a
stacking subtask is the object *below*, which the placed object hides. At 128×128 the head camera
sees a 4 cm block as a 3–4 pixel square and a stacked block's lower neighbour as a sliver one pixel
wide, so a centroid of whatever shows of the lower object is centimetres off. Instead each object's
silhouette is *rendered* from its known shape (a box, or a bowl: two circles and a lip) through the
rig's :class:`~calib.camera_model.CameraModel` at a hypothesised pose on a known plane, and the pose is
moved until the rendered coverage matches the object's colour mask on the pixels that could show it:
pixels of an occluder (an arm, a gripper) or of an object that may stand in front of it carry no
evidence either way. A visible edge then pins the pose even when the rest is hidden.

The coverage is rendered at ``SUPERSAMPLE``× the image resolution and area-averaged, so poses are
resolved to a fraction of a pixel. The search is a small pattern search (no SciPy): each step tries
± one step along every parameter and halves the steps when nothing improves.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass

import cv2
import numpy as np
from numpy.typing import NDArray

from calib.camera_model import CameraModel

SUPERSAMPLE = 4  # rendering resolution relative to the image (coverage in 1/16 pixel steps)
_SHIFT = 4  # cv2 fixed-point bits for polygon vertices (1/16 of a supersampled pixel)
CIRCLE_POINTS = 24  # points per circle of a bowl outline

FloatArray = NDArray[np.float64]
BoolArray = NDArray[np.bool_]


@dataclass(frozen=True)
class BoxShape:
    """A cube or block of edge ``edge`` [m] resting on its face (body origin at its centre)."""

    edge: float

    @property
    def height(self) -> float:
        return self.edge


@dataclass(frozen=True)
class BowlShape:
    """A bowl as built by ``simrig.objects.bowl_object``: flaring wall, vertical lip on top [m]."""

    bottom_radius: float
    top_radius: float
    height: float
    wall: float
    lip: float


Shape = BoxShape | BowlShape


@dataclass(frozen=True)
class Pose2D:
    """An upright object's pose: centre ``(x, y)`` in the rig frame, underside height ``z``, yaw [rad]."""

    x: float
    y: float
    z: float
    yaw: float = 0.0

    @property
    def xy(self) -> FloatArray:
        return np.array([self.x, self.y], dtype=np.float64)


def outline_points(shape: Shape, pose: Pose2D) -> FloatArray:
    """Rig-frame points ``(N, 3)`` whose projections' convex hull is the object's silhouette.

    An upright convex object's silhouette is the convex hull of its projected extreme points: a box's 8
    corners; a bowl's base circle, the top of its flaring wall and the top of its lip (the 12 wall
    plates are drawn as their circumscribing circle, < 2.5 mm off).
    """
    if isinstance(shape, BoxShape):
        h = shape.edge / 2
        c, s = math.cos(pose.yaw), math.sin(pose.yaw)
        corners = np.array([(a, b) for a in (-h, h) for b in (-h, h)], dtype=np.float64)
        xy = corners @ np.array([[c, s], [-s, c]]) + pose.xy
        z = np.array([pose.z, pose.z + shape.edge])
        return np.concatenate([np.column_stack([xy, np.full(4, zz)]) for zz in z], axis=0)
    phi = np.linspace(0.0, 2.0 * math.pi, CIRCLE_POINTS, endpoint=False)
    ring = np.column_stack([np.cos(phi), np.sin(phi)])
    outer = shape.top_radius + shape.wall / 2
    levels = (
        (shape.bottom_radius, pose.z),
        (outer, pose.z + shape.height - shape.lip),
        (outer, pose.z + shape.height + shape.wall / 2),
    )
    return np.concatenate([np.column_stack([pose.xy + r * ring, np.full(CIRCLE_POINTS, z)]) for r, z in levels], axis=0)


@dataclass(frozen=True)
class Window:
    """A pixel rectangle ``[u0, u0 + w) × [v0, v0 + h)``; it may reach past the image's borders."""

    u0: int
    v0: int
    w: int
    h: int

    def crop(self, image: BoolArray) -> BoolArray:
        """The window's part of a boolean image; pixels past the image's borders are False."""
        out = np.zeros((self.h, self.w), dtype=np.bool_)
        H, W = image.shape[:2]
        u0, v0 = max(self.u0, 0), max(self.v0, 0)
        u1, v1 = min(self.u0 + self.w, W), min(self.v0 + self.h, H)
        if u1 > u0 and v1 > v0:
            out[v0 - self.v0 : v1 - self.v0, u0 - self.u0 : u1 - self.u0] = image[v0:v1, u0:u1]
        return out


def silhouette_uv(camera: CameraModel, shape: Shape, pose: Pose2D) -> FloatArray | None:
    """The silhouette polygon's pixel coordinates ``(M, 2)``, or None if part of the object is behind the camera."""
    uv, _ = camera.project(outline_points(shape, pose))
    depth = camera.points_to_camera(outline_points(shape, pose))[:, 2]
    if not np.all(depth > 1e-3):
        return None
    hull = cv2.convexHull(uv.astype(np.float32)).reshape(-1, 2)
    return np.asarray(hull, dtype=np.float64)


def window_around(uv: FloatArray, margin: int, width: int, height: int) -> Window | None:
    """The rectangle around polygon ``uv`` grown by ``margin`` pixels, or None if it misses the image.

    It may reach past the image's borders (by at most one image size): a silhouette cut off by the
    border must count its outline out there as unseen, not as absent.
    """
    u0 = max(-width, math.floor(float(uv[:, 0].min())) - margin)
    v0 = max(-height, math.floor(float(uv[:, 1].min())) - margin)
    u1 = min(2 * width, math.ceil(float(uv[:, 0].max())) + margin + 1)
    v1 = min(2 * height, math.ceil(float(uv[:, 1].max())) + margin + 1)
    if u1 <= max(u0, 0) or v1 <= max(v0, 0) or u0 >= width or v0 >= height:
        return None
    return Window(u0, v0, u1 - u0, v1 - v0)


def coverage(uv: FloatArray, window: Window) -> NDArray[np.float32]:
    """Fraction ``(h, w)`` of each pixel of ``window`` inside polygon ``uv`` (pixel-centre convention)."""
    s = SUPERSAMPLE
    canvas = np.zeros((window.h * s, window.w * s), dtype=np.uint8)
    # A pixel (u, v) covers [u - 0.5, u + 0.5); supersampled pixel centres sit at (u + 0.5) s - 0.5.
    local = (uv - np.array([window.u0, window.v0], dtype=np.float64) + 0.5) * s - 0.5
    pts = np.round(local * (1 << _SHIFT)).astype(np.int32)
    cv2.fillConvexPoly(canvas, pts, 1, lineType=cv2.LINE_8, shift=_SHIFT)
    # Counting covered sub-pixels in integers and dividing once gives the box mean exactly (k / s², s² a
    # power of two). Rows of a block are summed by NumPy (a fast element-wise add of whole rows); the s
    # columns by s slice additions, since NumPy's reduction over a short last axis is what made this slow.
    # It runs for every pose the success judge tries.
    cols = canvas.reshape(window.h, s, window.w * s).sum(axis=1, dtype=np.uint16).reshape(window.h, window.w, s)
    hits = cols[..., 0]
    for k in range(1, s):
        hits = hits + cols[..., k]
    return np.asarray(hits.astype(np.float32) / np.float32(s * s), dtype=np.float32)


@dataclass(frozen=True)
class View:
    """One camera image prepared for fitting one object.

    ``mask`` ``(H, W)`` marks the object's colour; ``evidence`` ``(H, W)`` the pixels that may be used: not
    an occluder (an arm, a gripper) and not an object that may stand in front of this one.
    """

    camera: CameraModel
    mask: BoolArray
    evidence: BoolArray


@dataclass(frozen=True)
class ViewFit:
    """How a fitted silhouette sits in one view (areas in pixels).

    ``seen``: rendered area on evidence pixels; ``hidden``: rendered area on pixels without evidence;
    ``matched``: the part of ``seen`` that shows the object's colour; ``unexplained``: object-coloured
    evidence pixels outside the silhouette; ``edge_seen`` / ``edge_hidden``: outline pixels (partly
    covered, or on the silhouette's border) with and without evidence.
    """

    view: str
    seen: float
    hidden: float
    matched: float
    unexplained: float
    edge_seen: float
    edge_hidden: float
    colour_px: float  # evidence pixels of the object's colour in the whole image

    @property
    def visible_fraction(self) -> float:
        total = self.seen + self.hidden
        return self.seen / total if total > 0 else 0.0

    @property
    def edge_visible_fraction(self) -> float:
        """Share of the outline on evidence pixels: how much of its boundary this view pins down."""
        total = self.edge_seen + self.edge_hidden
        return self.edge_seen / total if total > 0 else 0.0

    @property
    def match_fraction(self) -> float:
        """Share of the rendered, evidence-carrying silhouette that shows the object's colour."""
        return self.matched / self.seen if self.seen > 0 else 0.0


@dataclass(frozen=True)
class Fit:
    """The best pose for one object, its cost (summed over the views) and how each view sees it."""

    pose: Pose2D
    cost: float
    views: tuple[ViewFit, ...]

    @property
    def explained_share(self) -> float:
        """Share of the object's colour (all views, whole images) that the silhouettes cover: low when the
        object is seen somewhere else than where the fit put it."""
        total = sum(v.colour_px for v in self.views)
        return sum(v.matched for v in self.views) / total if total > 0 else 1.0

    def best_view(self, min_edge_px: float = 4.0) -> ViewFit | None:
        """The view whose outline is best pinned down (at least ``min_edge_px`` outline pixels seen)."""
        cands = [v for v in self.views if v.edge_seen >= min_edge_px]
        return max(cands, key=lambda v: v.edge_visible_fraction) if cands else None


@dataclass
class _Prepared:
    camera: CameraModel
    window: Window
    mask: NDArray[np.float32]
    evidence: NDArray[np.float32]
    colour_px: float


def fit_pose(
    views: Sequence[View],
    shape: Shape,
    starts: Sequence[Pose2D],
    *,
    fit_yaw: bool | None = None,
    search_radius: float = 0.03,
    min_step: float = 0.0005,
) -> Fit | None:
    """The pose (within ``search_radius`` m of one of ``starts``, z fixed) whose silhouettes best match the masks.

    The cost is the squared difference between rendered coverage and mask over evidence pixels, summed
    over the views, on one fixed window per view that covers every pose the search may reach, so the
    searches from different starts are compared on the same pixels. Yaw is searched for boxes
    (``fit_yaw`` default) modulo their quarter-turn symmetry. Returns None if the object cannot be
    rendered into any view.
    """
    if not starts:
        raise ValueError("starts: expected at least one start pose")
    if fit_yaw is None:
        fit_yaw = isinstance(shape, BoxShape)
    prepared: list[_Prepared] = []
    for v in views:
        hulls = [silhouette_uv(v.camera, shape, p) for p in starts]
        if any(h is None for h in hulls):
            continue
        # Grow the starts' silhouettes by the search radius in pixels.
        margin = math.ceil(search_radius * max(_pixels_per_metre(v.camera, p) for p in starts)) + 2
        window = window_around(
            np.concatenate([h for h in hulls if h is not None]), margin, v.camera.width, v.camera.height
        )
        if window is None:
            continue
        mask, evidence = window.crop(v.mask), window.crop(v.evidence)
        colour_px = float(np.count_nonzero(v.mask & v.evidence))
        prepared.append(_Prepared(v.camera, window, mask.astype(np.float32), evidence.astype(np.float32), colour_px))
    if not prepared:
        return None

    def cost(p: Pose2D) -> tuple[float, list[NDArray[np.float32]] | None]:
        cs = []
        for pv in prepared:
            uv = silhouette_uv(pv.camera, shape, p)
            if uv is None:
                return math.inf, None
            cs.append(coverage(uv, pv.window))
        return sum(float(np.sum(pv.evidence * (c - pv.mask) ** 2)) for pv, c in zip(prepared, cs, strict=True)), cs

    best, best_cost, best_c = starts[0], math.inf, None
    for start in starts:
        pose, c0, cov = _pattern_search(cost, start, fit_yaw, search_radius, min_step)
        if c0 < best_cost:
            best, best_cost, best_c = pose, c0, cov
    if best_c is None:
        return None
    if fit_yaw:
        best = Pose2D(best.x, best.y, best.z, (best.yaw + math.pi / 4) % (math.pi / 2) - math.pi / 4)
    stats = []
    for pv, c in zip(prepared, best_c, strict=True):
        edge = _outline(c)
        stats.append(
            ViewFit(
                view=pv.camera.name,
                seen=float(np.sum(c * pv.evidence)),
                hidden=float(np.sum(c * (1.0 - pv.evidence))),
                matched=float(np.sum(c * pv.evidence * pv.mask)),
                unexplained=float(np.sum((1.0 - c) * pv.evidence * pv.mask)),
                edge_seen=float(np.sum(edge * pv.evidence)),
                edge_hidden=float(np.sum(edge * (1.0 - pv.evidence))),
                colour_px=pv.colour_px,
            )
        )
    return Fit(best, best_cost, tuple(stats))


_Cost = Callable[[Pose2D], tuple[float, list[NDArray[np.float32]] | None]]


def _pattern_search(
    cost: _Cost, start: Pose2D, fit_yaw: bool, radius: float, min_step: float
) -> tuple[Pose2D, float, list[NDArray[np.float32]] | None]:
    """Greedy ± steps along x, y (and yaw), halving the steps when none improves; stays within ``radius``."""
    best = start
    best_cost, best_c = cost(start)
    steps = [0.01, 0.01, 0.2 if fit_yaw else 0.0]  # x, y [m], yaw [rad]; a step of 0 is never tried
    floors = [min_step, min_step, 0.01]
    while any(s >= f for s, f in zip(steps, floors, strict=True) if s > 0):
        improved = False
        for k in range(3):
            if steps[k] <= 0 or steps[k] < floors[k]:
                continue
            for sign in (1.0, -1.0):
                d = [0.0, 0.0, 0.0]
                d[k] = sign * steps[k]
                cand = Pose2D(best.x + d[0], best.y + d[1], best.z, best.yaw + d[2])
                if math.hypot(cand.x - start.x, cand.y - start.y) > radius:
                    continue
                cc, c = cost(cand)
                if cc < best_cost - 1e-9:
                    best, best_cost, best_c, improved = cand, cc, c, True
                    break
            if improved:
                break
        if not improved:
            steps = [s / 2 for s in steps]
    return best, best_cost, best_c


def _outline(c: NDArray[np.float32]) -> NDArray[np.float32]:
    """Pixels on the silhouette's boundary: partly covered, or fully covered next to an uncovered one."""
    inside = (c >= 0.999).astype(np.uint8)
    eroded = cv2.erode(inside, np.ones((3, 3), np.uint8), borderType=cv2.BORDER_CONSTANT, borderValue=0)
    edge = ((c > 0.001) & (c < 0.999)) | ((inside == 1) & (eroded == 0))
    return np.asarray(edge, dtype=np.float32)


def _pixels_per_metre(camera: CameraModel, pose: Pose2D) -> float:
    """Image scale at ``pose``: pixels spanned by 1 cm along x and y there, per metre (the larger)."""
    p = np.array([[pose.x, pose.y, pose.z], [pose.x + 0.01, pose.y, pose.z], [pose.x, pose.y + 0.01, pose.z]])
    uv, _ = camera.project(p)
    return 100.0 * max(float(np.hypot(*(uv[1] - uv[0]))), float(np.hypot(*(uv[2] - uv[0]))))
