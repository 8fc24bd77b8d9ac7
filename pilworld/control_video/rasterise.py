"""The analytic robot renderer: the robot's convex primitives projected exactly and filled by OpenCV.

Every robot geom is convex (box, cylinder, capsule, sphere, ellipsoid; a mesh by its vertices' hull),
and a pinhole camera maps the convex hull of a point set onto the convex hull of the projected points.
So each geom's silhouette is the convex hull of the projection of a few generating points:

* box: its 8 corners (exact);
* cylinder: its two end circles (exact up to the polygon sampling of a circle);
* sphere: its silhouette circle, the circle where the cone of view rays touches it — centre
  ``c (1 − r²/|c|²)``, radius ``r √(|c|² − r²)/|c|``, in the plane normal to ``c`` (exact);
* capsule: the silhouette circles of its two end spheres (the capsule is their convex hull; exact).

Circles are sampled with ``CIRCLE_POINTS`` points on a radius between the inscribed and circumscribed
polygon (area error < 0.01 %). OpenCV fills every pixel whose square the polygon touches, half a pixel
more on each side than the pixel-centre rule of MuJoCo's (OpenGL's) rasteriser, so each geom is shrunk
by half a pixel at its depth before projecting. Geoms are filled far to near (painter's order by their
centres' distance) into a geom-index buffer, which gives part ids; geoms that cross the camera's near
plane (a wrist camera beside its own coupling) are clipped to it; lens distortion is applied by
rendering the pinhole image with a margin and remapping it.

Depth and shading are ray cast only at the pixels the robot covers, against the geom drawn there
(closed-form ray–box/cylinder/capsule/sphere intersections): the camera-frame depth Z and a headlight
Lambertian shade of the geom's colour. A pixel on a polygon's edge whose ray just misses the geom
takes the depth of the ray's closest approach to it.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any, Final

import cv2
import numpy as np
from numpy.typing import NDArray

from calib.camera_model import CameraModel
from pilworld.control_video import raycast
from pilworld.control_video.cameras import RigCameras
from pilworld.control_video.robot_frames import RobotRender
from pilworld.control_video.robot_model import (
    BOX,
    CAPSULE,
    CYLINDER,
    ELLIPSOID,
    GEOM_TYPE_NAMES,
    MESH,
    SPHERE,
    RobotModel,
)
from pilworld.types import STATE_DIM

CIRCLE_POINTS: Final = 20  # points per sampled circle
# OpenCV's polygon fill covers pixels its outline touches, not pixel centres; drawing 3× finer (inset by
# half a fine pixel) and reading the fine pixels at the coarse centres brings that error to a sixth of a
# pixel. Measured against MuJoCo's masks: see docs/control_video.md.
SUPERSAMPLE: Final = 3
_SHIFT: Final = 4  # OpenCV fixed-point bits: polygon vertices in 1/16 px
_ONE: Final = 1 << _SHIFT
AMBIENT: Final = 0.35  # shading: ambient + diffuse · cos(angle to the headlight), like MuJoCo's headlight
DIFFUSE: Final = 0.65
SUPPORTED: Final = (SPHERE, CAPSULE, ELLIPSOID, CYLINDER, BOX, MESH)

# Unit circle samples on the "mean" radius of the inscribed (cos) and circumscribed (1) polygons.
_ANG = np.linspace(0.0, 2.0 * math.pi, CIRCLE_POINTS, endpoint=False)
_CIRCLE = np.stack([np.cos(_ANG), np.sin(_ANG)], axis=-1) * (0.5 * (1.0 + 1.0 / math.cos(math.pi / CIRCLE_POINTS)))
_BOX_CORNERS = np.array([[sx, sy, sz] for sx in (-1, 1) for sy in (-1, 1) for sz in (-1, 1)], dtype=np.float64)
# A unit sphere's generating points for ellipsoids and for near-plane clipping of round geoms.
_golden = math.pi * (3.0 - math.sqrt(5.0))
_k = np.arange(48) + 0.5
_zs = 1.0 - 2.0 * _k / 48
_SPHERE_PTS = (
    np.stack([np.sqrt(1 - _zs**2) * np.cos(_golden * _k), np.sqrt(1 - _zs**2) * np.sin(_golden * _k), _zs], axis=-1)
    * 1.08
)  # circumscribe the 48-point hull roughly


def _lut(ids: NDArray[np.uint8], table: NDArray[np.uint8]) -> NDArray[np.uint8]:
    """``cv2.LUT`` of a (N, H, W) uint8 image stack, as one 2-D image.

    OpenCV reads a 3-D array as H × W × channels, and 5.x accepts at most 128 channels, so a stack of one
    224-pixel-wide frame would be refused; a 2-D view of the same bytes works on 4.x and 5.x alike.
    """
    flat = np.ascontiguousarray(ids).reshape(-1, ids.shape[-1])
    return np.asarray(cv2.LUT(flat, table), dtype=np.uint8).reshape(ids.shape)


@dataclass(frozen=True, eq=False)
class _ViewGrid:
    """What never changes for a view: the pinhole canvas it is drawn on and each pixel's ray."""

    K: NDArray[np.float64]  # pinhole intrinsics of the canvas (principal point shifted by the margin)
    width: int  # canvas size
    height: int
    rays32: NDArray[np.float32]  # (H_c, W_c, 3) ray directions (x, y, 1) of canvas pixels, camera frame
    planes: NDArray[np.float64]  # (4, 3) inward normals of the canvas frustum's side planes (through 0)
    remap: tuple[NDArray[np.float32], NDArray[np.float32]] | None  # output pixel → canvas pixel (distortion)
    out_size: tuple[int, int]  # (width, height) of the output image
    ss: int  # supersampling: the canvas is drawn ss× finer and sampled at the pixel centres

    @property
    def k_draw(self) -> NDArray[np.float64]:
        """Intrinsics of the ss× canvas: pixel centre u maps to ss·u + (ss − 1)/2, so sampling rows and
        columns (ss − 1)/2, (ss − 1)/2 + ss, … of it reads exactly the canvas pixel centres."""
        A = np.array([[self.ss, 0.0, (self.ss - 1) / 2], [0.0, self.ss, (self.ss - 1) / 2], [0.0, 0.0, 1.0]])
        out: NDArray[np.float64] = A @ self.K
        return out


def _view_grid(camera: CameraModel, ss: int, max_scale: float = 3.0) -> _ViewGrid:
    w, h = camera.width, camera.height
    K = camera.K.copy()
    if camera.dist.size == 0 or not np.any(camera.dist != 0):
        cw, ch, remap = w, h, None
    else:
        # Where each output pixel's ray lands on the undistorted image plane: the canvas must hold them.
        u, v = np.meshgrid(np.arange(w, dtype=np.float64), np.arange(h, dtype=np.float64))
        rays = camera.unproject(np.stack([u, v], axis=-1))
        with np.errstate(divide="ignore", invalid="ignore"):
            xn, yn = rays[..., 0] / rays[..., 2], rays[..., 1] / rays[..., 2]
        pu = K[0, 0] * xn + K[0, 1] * yn + K[0, 2]
        pv = K[1, 1] * yn + K[1, 2]
        ok = np.isfinite(pu) & np.isfinite(pv) & (rays[..., 2] > 0)
        lo_u = max(float(np.min(pu[ok])) - 2, -max_scale * w)
        hi_u = min(float(np.max(pu[ok])) + 2, (1 + max_scale) * w)
        lo_v = max(float(np.min(pv[ok])) - 2, -max_scale * h)
        hi_v = min(float(np.max(pv[ok])) + 2, (1 + max_scale) * h)
        ou, ov = math.floor(lo_u), math.floor(lo_v)
        cw, ch = math.ceil(hi_u) - ou + 1, math.ceil(hi_v) - ov + 1
        K[0, 2] -= ou
        K[1, 2] -= ov
        mu = np.where(ok, pu - ou, -1.0).astype(np.float32)
        mv = np.where(ok, pv - ov, -1.0).astype(np.float32)
        remap = (mu, mv)
    uc, vc = np.meshgrid(np.arange(cw, dtype=np.float64), np.arange(ch, dtype=np.float64))
    y = (vc - K[1, 2]) / K[1, 1]
    x = (uc - K[0, 2] - K[0, 1] * y) / K[0, 0]
    grid_rays = np.stack([x, y, np.ones_like(x)], axis=-1).astype(np.float32)
    # Side planes through the canvas border (one pixel beyond it), inward normals: a geom whose bounding
    # sphere lies beyond one of them cannot touch the canvas.
    corners = grid_rays[[0, 0, -1, -1], [0, -1, -1, 0]].astype(np.float64)
    pad = np.array([[-1, -1, 0], [1, -1, 0], [1, 1, 0], [-1, 1, 0]], dtype=np.float64)
    corners = corners + pad * np.array([1 / K[0, 0], 1 / K[1, 1], 0])
    planes = np.stack([np.cross(corners[i], corners[(i + 1) % 4]) for i in range(4)])
    planes /= np.linalg.norm(planes, axis=-1, keepdims=True)
    return _ViewGrid(K, cw, ch, grid_rays, planes, remap, (w, h), ss)


def _clip_to_box(poly: NDArray[Any], box: tuple[float, float, float, float]) -> NDArray[np.float64]:
    """Sutherland–Hodgman, vectorised per edge: a convex polygon (M, 2) clipped to the box (x0, y0, x1, y1)."""
    pts = np.asarray(poly, dtype=np.float64)
    for axis, bound, keep_less in ((0, box[0], False), (0, box[2], True), (1, box[1], False), (1, box[3], True)):
        if len(pts) == 0:
            break
        side = pts[:, axis] - bound
        inside = side <= 0 if keep_less else side >= 0
        if inside.all():
            continue
        nxt = np.roll(pts, -1, axis=0)
        side_n = np.roll(side, -1)
        crosses = inside != np.roll(inside, -1)
        with np.errstate(divide="ignore", invalid="ignore"):
            t = np.where(crosses, side / (side - side_n), 0.0)
        cut = pts + (nxt - pts) * t[:, None]
        # Each vertex emits itself if inside, then the crossing of its outgoing edge if there is one.
        both = np.stack([pts, cut], axis=1).reshape(-1, 2)
        keep = np.stack([inside, crosses], axis=1).reshape(-1)
        pts = both[keep]
    return pts


def _basis(n: NDArray[np.float64]) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Two unit vectors orthogonal to unit vectors ``n`` (..., 3) and to each other."""
    helper = np.where(np.abs(n[..., :1]) < 0.9, np.array([1.0, 0.0, 0.0]), np.array([0.0, 1.0, 0.0]))
    e1 = np.cross(n, helper)
    e1 /= np.linalg.norm(e1, axis=-1, keepdims=True)
    return e1, np.cross(n, e1)


class AnalyticRobotRenderer:
    """Render the robot of ``robot`` in every view of ``cameras`` (see the module docstring)."""

    def __init__(self, robot: RobotModel, cameras: RigCameras, supersample: int = SUPERSAMPLE) -> None:
        types = robot.geom_type
        bad = sorted({GEOM_TYPE_NAMES.get(int(t), str(int(t))) for t in types if t not in SUPPORTED})
        if bad:
            raise ValueError(
                f"robot model {robot.source}: geom types {bad} cannot be rasterised analytically "
                "(box, cylinder, capsule, sphere, ellipsoid, mesh); use backend='mujoco'"
            )
        self.robot = robot
        self.cameras = cameras
        self.types = types
        self.size = robot.geom_size
        self.part_lut = np.concatenate([[0], robot.geom_part]).astype(np.uint8)
        if len(self.part_lut) > 256:
            raise ValueError(f"robot model {robot.source}: {len(types)} geoms, the renderer draws at most 255")
        self.part_lut256 = np.zeros(256, dtype=np.uint8)
        self.part_lut256[: len(self.part_lut)] = self.part_lut
        self.rgb255 = (np.clip(robot.geom_rgba[:, :3], 0.0, 1.0) * 255.0).astype(np.float32)
        self.size32 = self.size.astype(np.float32)
        lut = np.zeros((3, 256), dtype=np.uint8)  # geom index + 1 → its colour, per channel
        lut[:, 1 : len(self.types) + 1] = np.rint(self.rgb255.T).astype(np.uint8)
        self.colour_lut = [np.ascontiguousarray(lut[c]) for c in range(3)]
        m = robot.model
        # MuJoCo clips at znear · extent; the reference renders (and the simulator's cameras) do too.
        self.near = float(m.vis.map.znear * m.stat.extent)
        if supersample not in (1, 3, 5):
            raise ValueError(
                f"supersample: expected 1, 3 or 5 (odd, so pixel centres are sub-pixel centres), got {supersample!r}"
            )
        self.grids = {v.name: _view_grid(v.model, supersample) for v in cameras.views}
        self._mesh_pts = self._mesh_points(robot)
        self._local = self._local_points()
        self.bound = self._bounding_radii()
        is_round = np.isin(types, (SPHERE, CAPSULE))
        self._round_idx = np.flatnonzero(is_round)
        self._flat_idx = np.flatnonzero(~is_round)
        self._round_half = np.where(types[is_round] == CAPSULE, self.size[is_round, 1], 0.0)
        # Per flat geom, the local extents its points are scaled against when shrinking (x, y, z).
        ext = self.size[~is_round].copy()
        cyl = types[~is_round] == CYLINDER
        ext[cyl] = np.stack([ext[cyl, 0], ext[cyl, 0], ext[cyl, 1]], axis=-1)
        mesh = types[~is_round] == MESH
        ext[mesh] = np.inf  # a mesh's points are its vertices; it is not shrunk
        self._flat_extent = np.maximum(ext, 1e-9)

    # ------------------------------------------------------------------ geometry

    @staticmethod
    def _mesh_points(robot: RobotModel) -> dict[int, NDArray[np.float64]]:
        m = robot.model
        out = {}
        for gi, (gid, t) in enumerate(zip(robot.geom_ids, robot.geom_type, strict=True)):
            if t == MESH:
                mid = int(m.geom_dataid[gid])
                start, n = int(m.mesh_vertadr[mid]), int(m.mesh_vertnum[mid])
                verts = np.asarray(m.mesh_vert[start : start + n], dtype=np.float64)
                step = max(1, n // 256)  # a hull from ≤ ~256 vertices: enough for a silhouette
                out[gi] = verts[::step]
        return out

    def _bounding_radii(self) -> NDArray[np.float64]:
        """(G,) radius of a sphere about each geom's centre that contains it."""
        t, s = self.types, self.size
        r = np.where(t == SPHERE, s[:, 0], 0.0)
        r = np.where(t == CAPSULE, s[:, 0] + s[:, 1], r)
        r = np.where(t == CYLINDER, np.hypot(s[:, 0], s[:, 1]), r)
        r = np.where(t == BOX, np.linalg.norm(s, axis=-1), r)
        r = np.where(t == ELLIPSOID, s.max(axis=-1), r)
        for g, pts in self._mesh_pts.items():
            r[g] = float(np.linalg.norm(pts, axis=-1).max())
        return r * 1.01

    def _local_points(self) -> NDArray[np.float64]:
        """(G, S, 3) view-independent generating points in each geom's frame (boxes, cylinders, ...).

        Spheres and capsules get theirs per view (silhouette circles); their rows here are unused.
        Shorter sets are padded by repeating their first point (the hull does not change).
        """
        S = max([2 * CIRCLE_POINTS, 48, *[len(p) for p in self._mesh_pts.values()]])
        out = np.zeros((len(self.types), S, 3))
        for g, (t, s) in enumerate(zip(self.types, self.size, strict=True)):
            if t == BOX:
                pts = _BOX_CORNERS * s
            elif t == CYLINDER:
                ring = np.concatenate([_CIRCLE * s[0], np.zeros((CIRCLE_POINTS, 1))], axis=-1)
                cap = np.array([0.0, 0.0, s[1]])
                pts = np.concatenate([ring + cap, ring - cap])
            elif t == ELLIPSOID:
                pts = _SPHERE_PTS * s
            elif t == MESH:
                pts = self._mesh_pts[g]
            else:
                pts = np.zeros((1, 3))
            out[g, : len(pts)] = pts
            out[g, len(pts) :] = pts[0]
        return out

    def _points_camera(
        self, Pc: NDArray[np.float64], Rc: NDArray[np.float64], shrink: NDArray[np.float64]
    ) -> NDArray[np.float64]:
        """(N, G, S, 3) generating points in the camera frame; ``shrink`` (N, G) metres off each surface."""
        N, G = Pc.shape[:2]
        S = self._local.shape[1]
        pts = np.empty((N, G, S, 3))
        flat, round_ = self._flat_idx, self._round_idx
        if flat.size:
            # Half a pixel inwards (see the module docstring): boxes lose it on every half-size, cylinders
            # on radius and half-length (the scale keeps the points on the shrunk surface).
            factor = np.clip(1.0 - shrink[:, flat, None] / self._flat_extent[None], 0.2, 1.0)  # (N, f, 3)
            local = self._local[flat][None] * factor[:, :, None, :]  # (N, f, S, 3)
            R = Rc[:, flat]  # (N, f, 3, 3)
            c = Pc[:, flat]
            world = np.empty_like(local)
            for k in range(3):
                world[..., k] = (
                    c[:, :, None, k]
                    + R[:, :, None, k, 0] * local[..., 0]
                    + R[:, :, None, k, 1] * local[..., 1]
                    + R[:, :, None, k, 2] * local[..., 2]
                )
            pts[:, flat] = world
        if round_.size:
            r = np.maximum(self.size[round_, 0][None] - shrink[:, round_], 1e-6)  # (N, g)
            half = self._round_half[None, :, None]
            axis = Rc[:, round_][..., 2]  # (N, g, 3)
            c = Pc[:, round_]
            ring_pts = np.concatenate([self._silhouette(c + half * axis, r), self._silhouette(c - half * axis, r)], 2)
            C = ring_pts.shape[2]
            pts[:, round_, :C] = ring_pts
            pts[:, round_, C:] = ring_pts[:, :, :1]
        return pts

    @staticmethod
    def _silhouette(c: NDArray[np.float64], r: NDArray[np.float64]) -> NDArray[np.float64]:
        """Silhouette circles (N, g, C, 3) of spheres at ``c`` (N, g, 3) with radii ``r`` (N, g)."""
        d2 = np.maximum(np.sum(c * c, axis=-1), (r * 1.0001) ** 2)
        d = np.sqrt(d2)
        n = c / d[..., None]
        centre = c * (1.0 - r * r / d2)[..., None]
        rho = r * np.sqrt(d2 - r * r) / d
        e1, e2 = _basis(n)
        ring = _CIRCLE[None, None, :, 0, None] * e1[:, :, None] + _CIRCLE[None, None, :, 1, None] * e2[:, :, None]
        out: NDArray[np.float64] = centre[:, :, None] + rho[..., None, None] * ring
        return out

    def _near_clipped(self, g: int, Pc: NDArray[np.float64], Rc: NDArray[np.float64]) -> NDArray[np.float64] | None:
        """A geom crossing the near plane: its (approximate) hull points clipped to z ≥ near, or None."""
        t, s = self.types[g], self.size[g]
        if t in (SPHERE, CAPSULE):
            half = s[1] if t == CAPSULE else 0.0
            sph = _SPHERE_PTS * s[0]
            cap = np.array([0.0, 0.0, half])
            local = np.concatenate([sph + cap, sph - cap])
        else:
            local = self._local[g]
        pts = Pc + local @ Rc.T
        inside = pts[:, 2] >= self.near
        if not np.any(inside):
            return None
        a, b = pts[inside], pts[~inside]
        if b.size:
            # hull(P) ∩ {z ≥ near}: the points inside plus every segment's crossing of the plane.
            ta = (a[:, None, 2] - self.near) / (a[:, None, 2] - b[None, :, 2])
            cross = a[:, None] + ta[..., None] * (b[None] - a[:, None])
            a = np.concatenate([a, cross.reshape(-1, 3)])
            a[:, 2] = np.maximum(a[:, 2], self.near)
        return a

    def _contains_camera(self, Pc: NDArray[np.float64], Rc: NDArray[np.float64]) -> NDArray[np.bool_]:
        """(N, G) True where the camera sits inside a geom: MuJoCo culls back faces, so such a geom is unseen."""
        o = -np.einsum("ngji,ngj->ngi", Rc, Pc)  # camera centre in each geom's frame
        s = self.size[None]
        t = self.types[None]
        radial2 = o[..., 0] ** 2 + o[..., 1] ** 2
        zc = np.maximum(np.abs(o[..., 2]) - s[..., 1], 0.0)
        inside = np.where(t == BOX, np.all(np.abs(o) <= s, axis=-1), False)
        inside |= (t == CYLINDER) & (radial2 <= s[..., 0] ** 2) & (np.abs(o[..., 2]) <= s[..., 1])
        inside |= (t == CAPSULE) & (radial2 + zc**2 <= s[..., 0] ** 2)
        inside |= (t == SPHERE) & (np.sum(o * o, axis=-1) <= s[..., 0] ** 2)
        inside |= (t == ELLIPSOID) & (np.sum((o / np.maximum(s, 1e-12)) ** 2, axis=-1) <= 1.0)
        return inside

    # ------------------------------------------------------------------ drawing

    def render(
        self,
        q14: NDArray[np.floating],
        *,
        depth: bool = True,
        shaded: bool = True,
        views: Sequence[str] | None = None,
    ) -> RobotRender:
        """Render joint vectors (N, 14) (or one (14,)) in every view (or in ``views``); see :class:`RobotRender`."""
        q = np.asarray(q14, dtype=np.float64)
        if q.ndim not in (1, 2) or q.shape[-1] != STATE_DIM:
            raise ValueError(f"q14: expected joint vectors (N, {STATE_DIM}) or ({STATE_DIM},), got shape {q.shape}")
        if not np.all(np.isfinite(q)):
            bad = np.argwhere(~np.isfinite(q.reshape(-1, STATE_DIM)))[0].tolist()
            raise ValueError(f"q14: contains non-finite values (first at [frame, index] {bad})")
        q = q.reshape(-1, STATE_DIM)
        pos, rot = self.robot.geom_poses(q)  # (N, G, 3), (N, G, 3, 3) rig frame
        poses = self.cameras.poses(q)
        parts: dict[str, NDArray[np.uint8]] = {}
        depths: dict[str, NDArray[np.float32]] = {}
        shades: dict[str, NDArray[np.uint8]] = {}
        for view in self.cameras.views:
            if views is not None and view.name not in views:
                continue
            T = poses[view.name]  # (N, 4, 4)
            R, t = T[:, :3, :3], T[:, :3, 3]
            Pc = np.einsum("nij,ngj->ngi", R, pos) + t[:, None]
            Rc = R[:, None] @ rot
            grid = self.grids[view.name]
            ids = self._draw(Pc, Rc, grid)  # (N, H_c, W_c) geom index + 1
            out_parts: NDArray[np.uint8] = _lut(ids, self.part_lut256)
            if depth or shaded:
                z, shade = self._cast(ids, Pc, Rc, grid)
            if grid.remap is not None:
                out_parts = self._remap(out_parts, grid)
                ids = self._remap(ids, grid)
                if depth or shaded:
                    z = self._remap(z, grid)
                    shade = self._remap(shade, grid)
            parts[view.name] = out_parts
            if depth:
                depths[view.name] = z
            if shaded:
                shades[view.name] = shade
        return RobotRender(parts, depths if depth else None, shades if shaded else None)

    @staticmethod
    def _remap(img: NDArray[Any], grid: _ViewGrid) -> NDArray[Any]:
        assert grid.remap is not None
        mu, mv = grid.remap
        out = [cv2.remap(f, mu, mv, cv2.INTER_NEAREST, borderMode=cv2.BORDER_CONSTANT, borderValue=0) for f in img]
        return np.stack(out)

    def _draw(self, Pc: NDArray[np.float64], Rc: NDArray[np.float64], grid: _ViewGrid) -> NDArray[np.uint8]:
        N = Pc.shape[0]
        K = grid.k_draw
        ss = grid.ss
        f = 0.5 * (K[0, 0] + K[1, 1])
        zc = np.maximum(Pc[..., 2], self.near)
        shrink = 0.5 * zc / f  # half a pixel at each geom's depth, metres
        pts = self._points_camera(Pc, Rc, shrink)  # (N, G, S, 3)
        z = pts[..., 2]
        zmin, zmax = z.min(axis=-1), z.max(axis=-1)
        with np.errstate(divide="ignore", invalid="ignore"):
            x, y = pts[..., 0] / z, pts[..., 1] / z
        u = K[0, 0] * x + K[0, 1] * y + K[0, 2]
        v = K[1, 1] * y + K[1, 2]
        W, H = grid.width * ss, grid.height * ss
        front = zmin >= self.near
        # Bounding spheres outside the canvas frustum (or wholly behind the near plane) are never drawn.
        inside = np.all(Pc @ grid.planes.T > -self.bound[None, :, None], axis=-1) & (zmax >= self.near)
        ok = front & inside & (u.max(-1) > -1) & (u.min(-1) < W) & (v.max(-1) > -1) & (v.min(-1) < H)
        crossing = inside & ~front & ~self._contains_camera(Pc, Rc)
        uv = np.stack([u, v], axis=-1)
        # Polygons reaching far beyond the canvas (a geom beside a wrist camera) are clipped to it exactly
        # (clamping their vertices would bend their edges); the rest go straight to fixed point.
        lim = 4.0 * max(W, H)
        far = np.any(np.abs(uv) > lim, axis=(-1, -2))
        fixed = np.rint(np.clip(uv, -lim, lim) * _ONE).astype(np.int32)  # (N, G, S, 2)
        box = (-2.0, -2.0, W + 1.0, H + 1.0)
        order = np.argsort(-np.linalg.norm(Pc, axis=-1), axis=1)  # far to near, per frame
        ids = np.zeros((N, H, W), dtype=np.uint8)
        hull, fill = cv2.convexHull, cv2.fillConvexPoly
        cut: list[list[tuple[int, NDArray[np.int32]]]] = [[] for _ in range(N)]  # near-plane-cut geoms per frame
        for n in range(N):
            img = ids[n]
            ok_n, cross_n = ok[n], crossing[n]
            for g in order[n].tolist():
                if ok_n[g]:
                    if far[n, g]:
                        poly = _clip_to_box(np.asarray(cv2.convexHull(uv[n, g].astype(np.float32)))[:, 0], box)
                        if len(poly) >= 3:
                            fill(img, np.rint(poly * _ONE).astype(np.int32), g + 1, cv2.LINE_8, _SHIFT)
                    else:
                        fill(img, hull(fixed[n, g]), g + 1, cv2.LINE_8, _SHIFT)
                elif cross_n[g]:
                    cp = self._near_clipped(g, Pc[n, g], Rc[n, g])
                    if cp is None:
                        continue
                    cu = K[0, 0] * cp[:, 0] / cp[:, 2] + K[0, 1] * cp[:, 1] / cp[:, 2] + K[0, 2]
                    cv_ = K[1, 1] * cp[:, 1] / cp[:, 2] + K[1, 2]
                    flat_pts = np.stack([cu, cv_], -1).astype(np.float32)
                    poly = np.asarray(cv2.convexHull(flat_pts))[:, 0].astype(np.float64)
                    if np.abs(poly).max() > lim:  # only a hull reaching far out needs exact clipping
                        poly = _clip_to_box(poly, box)
                    if len(poly) >= 3:
                        cut[n].append((g, np.rint(poly * _ONE).astype(np.int32)))
        o = (ss - 1) // 2
        out = np.ascontiguousarray(ids[:, o::ss, o::ss]) if ss > 1 else ids
        if any(cut):
            self._composite_cut(out, cut, Pc, Rc, grid)
        return out

    # ------------------------------------------------------------------ depth and shading

    def _intersect(
        self,
        pix: NDArray[np.int64],
        g: NDArray[np.int64],
        Pc: NDArray[np.float64],
        Rc: NDArray[np.float64],
        grid: _ViewGrid,
    ) -> tuple[NDArray[np.int64], NDArray[np.int64], tuple[Any, ...], tuple[Any, ...], NDArray[np.int64]]:
        """Rays of flat pixel indices ``pix`` of (N, H, W) against geoms ``g`` (one per pixel).

        Returns the pixels and geoms regrouped by primitive kind, ``(t, nx, ny, nz)`` (t = depth Z, inf
        where the ray misses), the ray directions ``e`` in the geom frames and the (frame·G + geom) index.
        """
        H, W = grid.height, grid.width
        G = Pc.shape[1]
        # Pixels grouped by primitive kind, so each kind's rays are one contiguous slice below.
        perm = np.argsort(self.types[g], kind="stable")
        pix, g = pix[perm], g[perm]
        n_idx = pix // (H * W)
        ng = n_idx * G + g
        yx = pix % (H * W)
        # Ray (x, y, 1) in the camera frame, so t is the depth Z; in the geom's frame: o = −Rᵀc, e = Rᵀd.
        rays = grid.rays32.reshape(-1, 3)
        dx, dy = rays[yx, 0], rays[yx, 1]
        # Per (frame, geom) first, then gathered per pixel one contiguous component at a time.
        Rf = Rc.reshape(-1, 3, 3)
        cf = Pc.reshape(-1, 3)
        o_ng = -np.einsum("mjk,mj->km", Rf, cf).astype(np.float32)  # (3, N·G)
        R_ng = Rf.reshape(-1, 9).T.astype(np.float32)  # (9, N·G), row 3j + k = R[j, k]
        o = (o_ng[0][ng], o_ng[1][ng], o_ng[2][ng])
        e = tuple(R_ng[k][ng] * dx + R_ng[3 + k][ng] * dy + R_ng[6 + k][ng] for k in range(3))
        s0, s1, s2 = (self.size32[:, k][g] for k in range(3))
        kinds = self.types[g]
        t = np.full(g.shape, np.inf, dtype=np.float32)
        nx, ny, nz = np.zeros_like(t), np.zeros_like(t), np.zeros_like(t)
        bounds = np.searchsorted(kinds, np.arange(kinds.max() + 2))
        for kind in (BOX, CYLINDER, CAPSULE, SPHERE, ELLIPSOID):
            if kind > kinds[-1] or bounds[kind] == bounds[kind + 1]:
                continue
            sel = slice(int(bounds[kind]), int(bounds[kind + 1]))
            os_ = (o[0][sel], o[1][sel], o[2][sel])
            es = (e[0][sel], e[1][sel], e[2][sel])
            ss = (s0[sel], s1[sel], s2[sel])
            if kind == BOX:
                hit = raycast.hit_box(os_, es, ss)
            elif kind == CYLINDER:
                hit = raycast.hit_cylinder(os_, es, ss[0], ss[1])
            elif kind == CAPSULE:
                hit = raycast.hit_capsule(os_, es, ss[0], ss[1])
            elif kind == SPHERE:
                hit = raycast.hit_sphere(os_, es, ss[0])
            else:  # an ellipsoid is the unit sphere in coordinates scaled by its half-axes
                sc = ss
                th = raycast.hit_sphere(
                    (os_[0] / sc[0], os_[1] / sc[1], os_[2] / sc[2]),
                    (es[0] / sc[0], es[1] / sc[1], es[2] / sc[2]),
                    np.ones_like(sc[0]),
                )
                hit = (th[0], th[1] / sc[0], th[2] / sc[1], th[3] / sc[2])
            t[sel], nx[sel], ny[sel], nz[sel] = hit
        return pix, g, (t, nx, ny, nz), e, ng

    def _composite_cut(
        self,
        ids: NDArray[np.uint8],
        cut: list[list[tuple[int, NDArray[np.int32]]]],
        Pc: NDArray[np.float64],
        Rc: NDArray[np.float64],
        grid: _ViewGrid,
    ) -> None:
        """Add the geoms the near plane cuts, z-tested per pixel against what is drawn (``ids`` at 1×).

        MuJoCo (OpenGL) clips at the near plane and culls back faces, so where a geom's front surface is
        cut away one sees through it, not into it: a pixel shows the geom only where its ray enters the
        geom beyond the near plane. The polygon of the clipped volume (``cut``, fixed point on the ss×
        canvas) is a superset of those pixels; each is ray cast, and wins where it is nearer than the
        geom already there. Frames are batched: round r takes the r-th cut geom of every frame.
        """
        N, H, W = ids.shape
        ss, o = grid.ss, (grid.ss - 1) // 2
        scratch = np.zeros((N, H * ss, W * ss), dtype=np.uint8)  # polygon of frame n filled with geom + 1
        for r in range(max(len(c) for c in cut)):
            scratch.fill(0)
            for n in range(N):
                if r < len(cut[n]):
                    geom, poly = cut[n][r]
                    cv2.fillConvexPoly(scratch[n], poly, geom + 1, cv2.LINE_8, _SHIFT)
            sampled = scratch[:, o::ss, o::ss]
            pix = np.flatnonzero(sampled)
            if pix.size == 0:
                continue
            g_in = sampled.reshape(-1)[pix].astype(np.int64) - 1
            pix, g, (t, *_), _, _ = self._intersect(pix, g_in, Pc, Rc, grid)
            seen = t >= self.near  # inf (a miss) never wins below
            keep = seen & np.isfinite(t)
            pix, g, t = pix[keep], g[keep], t[keep]
            flat = ids.reshape(-1)
            other = flat[pix].astype(np.int64) - 1
            win = other < 0
            drawn = np.flatnonzero(~win)
            if drawn.size:
                p2, _, (t2, *_), _, _ = self._intersect(pix[drawn], other[drawn], Pc, Rc, grid)
                t_other = np.full(pix.size, np.inf, dtype=np.float32)
                order = np.argsort(pix[drawn])
                # _intersect regroups its inputs; map its results back to drawn's order through the pixel ids.
                t_other[drawn[order]] = t2[np.argsort(p2)]
                win |= t < t_other
            flat[pix[win]] = (g[win] + 1).astype(np.uint8)

    def _cast(
        self, ids: NDArray[np.uint8], Pc: NDArray[np.float64], Rc: NDArray[np.float64], grid: _ViewGrid
    ) -> tuple[NDArray[np.float32], NDArray[np.uint8]]:
        """Depth Z (N, H, W) and shaded RGB (N, H, W, 3) at the robot's pixels."""
        N, H, W = ids.shape
        z_img = np.zeros((N, H, W), dtype=np.float32)
        shade_img = np.zeros((N, H, W, 3), dtype=np.uint8)
        flat = ids.reshape(-1)
        pix = np.flatnonzero(flat)
        if pix.size == 0:
            return z_img, shade_img
        g = flat[pix].astype(np.int64) - 1
        pix, g, (t, nx, ny, nz), e, ng = self._intersect(pix, g, Pc, Rc, grid)
        rays = grid.rays32.reshape(-1, 3)
        yx = pix % (H * W)
        dx, dy = rays[yx, 0], rays[yx, 1]
        cf = Pc.reshape(-1, 3)
        cz = cf[:, 2].astype(np.float32)
        c_ng = cf.T.astype(np.float32)
        miss = np.flatnonzero(~np.isfinite(t))
        if miss.size:
            # Polygon-edge pixels whose ray grazes past the geom: the ray's closest approach to its centre.
            m_ng = ng[miss]
            dxm, dym = dx[miss], dy[miss]
            t[miss] = (dxm * c_ng[0][m_ng] + dym * c_ng[1][m_ng] + cz[m_ng]) / (dxm * dxm + dym * dym + 1)
            nx[miss], ny[miss], nz[miss] = -e[0][miss], -e[1][miss], -e[2][miss]
        t = np.maximum(t, np.float32(self.near))
        z_img.reshape(-1)[pix] = t
        # Headlight shading: the light sits at the camera, so cos = n · (−e) / (|n| |e|) in the geom frame.
        dot = -(nx * e[0] + ny * e[1] + nz * e[2])
        norm = np.sqrt((nx * nx + ny * ny + nz * nz) * (e[0] * e[0] + e[1] * e[1] + e[2] * e[2]))
        cosang = np.clip(dot / np.maximum(norm, np.float32(1e-12)), 0.0, 1.0)
        light = np.zeros(N * H * W, dtype=np.float32)
        light[pix] = np.float32(AMBIENT) + np.float32(DIFFUSE) * cosang
        light_img = light.reshape(N, H, W)
        # Colour by geom through per-channel lookup tables (OpenCV, uint8 → uint8), then the light.
        for ch in range(3):
            base = _lut(ids, self.colour_lut[ch]).astype(np.float32)
            shade_img[..., ch] = np.minimum(base * light_img + 0.5, 255)
        return z_img, shade_img
