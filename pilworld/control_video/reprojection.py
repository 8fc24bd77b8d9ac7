"""The scene reprojection prior of Γ⁺: each view's current frame warped into its future camera poses.

A wrist camera rides on its gripper, so most of what it will see in the next K frames is the same table
seen from a new pose. Assuming the scene is the plane ``z = plane_z`` of the rig frame (the table
surface, ``z = 0``), geometry alone predicts those frames; the world model is left with what the plane
cannot explain (objects above it, disocclusion, the arm itself, lighting).

**Plane homography.** A camera with intrinsics ``K`` and pose ``T_cam_rig = [R | t]`` sees the plane
point ``X = (x, y, z₀)`` at ``p ~ K (r₁ x + r₂ y + r₃ z₀ + t) = H (x, y, 1)ᵀ`` with
``H = K [r₁ r₂ r₃ z₀ + t]``. A target pixel ``p_t`` of the future pose therefore shows the source pixel
``p_s ~ H_s H_t⁻¹ p_t`` (one 3×3 matrix per source view and target pose, applied by
``cv2.warpPerspective``). The plane point lies in front of the target camera iff ``(H_t⁻¹ p_t)₃ > 0``
and in front of the source camera iff additionally ``(H_s H_t⁻¹ p_t)₃ > 0``; both are linear in
``p_t``, so whole frames are decided from their four corners and only mixed frames are tested per pixel.

**Lens distortion.** With distortion on either camera the map is no homography. Then every target
pixel's ray (``CameraModel.unproject``, once per camera) is intersected with the plane and projected
into the source camera with its distortion (``CameraModel.project``); the K maps are stacked into one
``cv2.remap`` call.

**Sources and validity.** Each target pixel is filled from its own view's current frame (source 1); where
that has nothing (the plane point projects outside it, lies behind a camera, or falls on robot pixels
of the current frame), a wrist view falls back to the head view's current frame warped the same way
(source 2); else it stays empty (source 0, black). Source pixels covered by the robot in the current
frame are never used (they are not table): the warp carries a validity channel, and a target pixel
counts only if every bilinear tap is a valid source pixel (the border of the image and of the robot is
therefore lost by up to a pixel, as it should: those colours are mixed). Target pixels where the robot
will be in the future frame are invalid too (the robot render covers them). A static camera (the head
view) is its own future: its prior is the current frame with the robot removed. Head pixels used for a
wrist view are first scaled per channel to the wrist camera's colours (``match_head_colour``). Points on the plane
beyond the table's edge are warped like any other (the plane is the approximation; docs/control_video_prior.md
measures where it breaks).

Speed: pixel grids and rays are precomputed per camera; homographies are batched over K in NumPy; the
images go through OpenCV (call ``cv2.setNumThreads(1)`` in a worker, as the benches do); an RGBA pixel
is packed into one ``uint32`` so that compositing is one ``np.where`` per view. About 6 ms per chunk
(K = 15, three views, robot masks) at 128×128 on one core (``python -m pilworld.bench.reprojection``).
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any, Final

import cv2
import numpy as np
from numpy.typing import NDArray

from calib.camera_model import NEAR_Z, CameraModel
from pilworld.control_video.cameras import RigCameras, ViewCamera
from pilworld.types import HEAD_VIEW, STATE_DIM

__all__ = [
    "SOURCE_HEAD",
    "SOURCE_NONE",
    "SOURCE_OWN",
    "ReprojectionPrior",
    "SceneReprojector",
    "plane_homography",
    "warp_through_plane",
]

SOURCE_NONE: Final = 0  #: nothing fills the pixel (outside every source, behind a camera, robot)
SOURCE_OWN: Final = 1  #: filled from the view's own current frame
SOURCE_HEAD: Final = 2  #: filled from the head view's current frame (wrist views only)

_INTERPOLATIONS: Final = {"linear": cv2.INTER_LINEAR, "nearest": cv2.INTER_NEAREST}
_FULL: Final = 255  # validity channel of a usable source pixel
_OFF_IMAGE: Final = -1.0e4  # remap coordinate of a target pixel without a source (lands in the border)
_METHODS: Final = ("auto", "homography", "remap")
_PACKED: Final = np.dtype("<u4")  # an RGBA pixel as one little-endian word: alpha is the top byte
_ALPHA_FULL: Final = np.uint32(_FULL << 24)
_MIN_MATCH_FRACTION: Final = 0.05  # head/wrist overlap needed to estimate a colour gain
_MATCH_SAMPLES: Final = 2048  # overlap pixels the colour gain is estimated from (a strided subsample)
_GAIN_RANGE: Final = (0.5, 2.0)  # a larger correction is a failed estimate, not an exposure difference
#: Pixels within this fraction of the image size of the future robot (4 px at 128²) have no prior; measured
#: in docs/control_video_prior.md (wrist gain at k = 15: +2.86 dB without, +3.13 dB with, 71 → 67 % valid).
ROBOT_MARGIN: Final = 1 / 32

U8 = NDArray[np.uint8]
Bool = NDArray[np.bool_]
F64 = NDArray[np.float64]


@dataclass(frozen=True, eq=False)
class ReprojectionPrior:
    """The prior for one chunk: per view, K warped frames and which source filled each pixel."""

    images: dict[str, U8]  # view → (K, H, W, 3) RGB; black where source == SOURCE_NONE
    source: dict[str, U8]  # view → (K, H, W): SOURCE_NONE 0, SOURCE_OWN 1, SOURCE_HEAD 2

    @property
    def valid(self) -> dict[str, Bool]:
        """view → (K, H, W) bool: the pixel has a prior (source ≠ 0)."""
        return {v: s != SOURCE_NONE for v, s in self.source.items()}

    @property
    def views(self) -> tuple[str, ...]:
        return tuple(self.images)

    @property
    def frames(self) -> int:
        return next(iter(self.images.values())).shape[0] if self.images else 0


def plane_homography(K: F64, T_cam_rig: F64, plane_z: float = 0.0) -> F64:
    """``H = K [r₁ r₂ r₃ z₀ + t]`` (..., 3, 3): rig-frame plane coordinates (x, y, 1) → pixels."""
    T = np.asarray(T_cam_rig, dtype=np.float64)
    M = np.empty((*T.shape[:-2], 3, 3), dtype=np.float64)
    M[..., :, 0] = T[..., :3, 0]
    M[..., :, 1] = T[..., :3, 1]
    M[..., :, 2] = T[..., :3, 2] * plane_z + T[..., :3, 3]
    return np.asarray(K, dtype=np.float64) @ M


def _has_distortion(model: CameraModel) -> bool:
    return bool(np.any(model.dist != 0.0))


@dataclass(frozen=True, eq=False)
class _TargetGrid:
    """Precomputed pixel grid of one camera: homogeneous centres and (if distorted) its unit rays."""

    model: CameraModel
    pixels: F64 = field(init=False)  # (3, H·W) homogeneous pixel centres, row-major
    corners: F64 = field(init=False)  # (3, 4) the outermost pixel centres
    rays: F64 | None = field(init=False)  # (H·W, 3) camera-frame unit rays (NaN: no ray), distorted only

    def __post_init__(self) -> None:
        w, h = self.model.width, self.model.height
        v, u = np.mgrid[0:h, 0:w].astype(np.float64)
        pixels = np.stack([u.ravel(), v.ravel(), np.ones(h * w)])
        corners = np.array([[0.0, w - 1.0, 0.0, w - 1.0], [0.0, 0.0, h - 1.0, h - 1.0], [1.0] * 4])
        rays = self.model.unproject(pixels[:2].T) if _has_distortion(self.model) else None
        object.__setattr__(self, "pixels", pixels)
        object.__setattr__(self, "corners", corners)
        object.__setattr__(self, "rays", rays)


def _positive(rows: F64, grid: _TargetGrid) -> Bool:
    """(K, H·W) bool: every linear form of ``rows`` (K, n, 3) is > 0 at the pixel (corner shortcut)."""
    k = rows.shape[0]
    at_corners = rows @ grid.corners  # (K, n, 4): a linear form's extremes over the image are at corners
    all_pos = (at_corners > 0.0).all(axis=(1, 2))
    any_neg = np.any(np.all(at_corners <= 0.0, axis=2), axis=1)  # one form ≤ 0 everywhere: nothing in front
    out = np.empty((k, grid.pixels.shape[1]), dtype=np.bool_)
    out[all_pos] = True
    out[any_neg & ~all_pos] = False
    mixed = ~all_pos & ~any_neg
    if mixed.any():
        vals = rows[mixed] @ grid.pixels  # (m, n, H·W)
        out[mixed] = (vals > 0.0).all(axis=1)
    return out


def _with_alpha(image: U8, usable: Bool | None) -> U8:
    """(H, W, 4) uint8: RGB plus the validity channel (255 where the pixel may be used as a source)."""
    h, w = image.shape[:2]
    out = np.empty((h, w, 4), dtype=np.uint8)
    out[..., :3] = image
    if usable is None:
        out[..., 3] = _FULL
    else:
        np.multiply(usable, _FULL, out=out[..., 3], casting="unsafe")
    return out


def _use_remap(source: CameraModel, target: CameraModel, method: str) -> bool:
    distorted = _has_distortion(source) or _has_distortion(target)
    if method == "homography" and distorted:
        raise ValueError("method: 'homography' needs two undistorted cameras; use 'auto' or 'remap'")
    return method == "remap" or (method == "auto" and distorted)


def _warp_rgba(
    src4: U8,
    source: CameraModel,
    T_source: F64,
    grid: _TargetGrid,
    T_t: F64,
    plane_z: float,
    flag: int,
    use_remap: bool,
) -> tuple[NDArray[np.uint32], Bool]:
    """The RGBA source warped into the K target poses, as one uint32 per pixel (K, H, W), and validity.

    A pixel is valid where the plane point is in front of both cameras, lands inside the source image
    and every bilinear tap is a usable source pixel (the warped validity channel is exactly 255).
    """
    if use_remap:
        warped, ok = _remap(src4, source.with_pose(T_source), grid, T_t, plane_z, flag)
    else:
        warped, ok = _homography_warp(src4, source.K, T_source, grid, T_t, plane_z, flag)
    packed = warped.view(_PACKED)[..., 0]  # (K, H, W): bytes R, G, B, A; A is the most significant
    ok &= packed >= _ALPHA_FULL
    return packed, ok


def _unpack(packed: NDArray[np.uint32]) -> U8:
    """(K, H, W) packed RGBA → contiguous (K, H, W, 3) RGB."""
    k, h, w = packed.shape
    rgba = packed.view(np.uint8).reshape(k * h, w, 4)
    return np.asarray(cv2.cvtColor(rgba, cv2.COLOR_RGBA2RGB), dtype=np.uint8).reshape(k, h, w, 3)


def warp_through_plane(
    image: U8,
    usable: Bool | None,
    source: CameraModel,
    target: CameraModel,
    T_target: F64,
    *,
    plane_z: float = 0.0,
    interpolation: str = "linear",
    method: str = "auto",
) -> tuple[U8, Bool]:
    """Warp ``image`` (H_s, W_s, 3) of ``source`` (posed: its ``T_cam_base`` is ``T_cam_rig``) into the
    K poses ``T_target`` (K, 4, 4) of camera ``target`` (intrinsics, distortion, size) via the plane.

    ``usable`` (H_s, W_s) marks source pixels that may be used (None: all). Returns the warped images
    (K, H, W, 3) (black where invalid) and the validity (K, H, W). ``method`` is ``"auto"`` (homography
    for two undistorted cameras, else the unproject → plane → project remap), ``"homography"`` or
    ``"remap"``; ``interpolation`` is ``"linear"`` or ``"nearest"`` (for label images).
    """
    if interpolation not in _INTERPOLATIONS:
        raise ValueError(f"interpolation: expected one of {sorted(_INTERPOLATIONS)}, got {interpolation!r}")
    if method not in _METHODS:
        raise ValueError(f"method: expected one of {list(_METHODS)}, got {method!r}")
    T_t = np.asarray(T_target, dtype=np.float64).reshape(-1, 4, 4)
    src4 = _with_alpha(np.asarray(image, dtype=np.uint8), usable)
    use_remap = _use_remap(source, target, method)
    packed, ok = _warp_rgba(
        src4, source, source.T_cam_base, _TargetGrid(target), T_t, plane_z, _INTERPOLATIONS[interpolation], use_remap
    )
    return _unpack(np.where(ok, packed, np.uint32(0))), ok


def _homography_warp(
    src4: U8, K_s: F64, T_s: F64, grid: _TargetGrid, T_t: F64, plane_z: float, flag: int
) -> tuple[U8, Bool]:
    target = grid.model
    k, h, w = T_t.shape[0], target.height, target.width
    H_s = plane_homography(K_s, T_s, plane_z)
    H_t_inv = np.linalg.inv(plane_homography(target.K, T_t, plane_z))  # (K, 3, 3) target pixel → plane
    M = H_s @ H_t_inv  # (K, 3, 3) target pixel → source pixel
    # Depth signs: (H_t⁻¹ p)₃ = 1 / depth_t and (M p)₃ = depth_s / depth_t (see the module docstring).
    rows = np.stack([H_t_inv[:, 2], M[:, 2]], axis=1)  # (K, 2, 3)
    ok = _positive(rows, grid).reshape(k, h, w)
    warped = np.empty((k, h, w, 4), dtype=np.uint8)
    for i in range(k):
        cv2.warpPerspective(
            src4,
            M[i],
            (w, h),
            dst=warped[i],
            flags=flag | cv2.WARP_INVERSE_MAP,
            borderMode=cv2.BORDER_CONSTANT,
            borderValue=(0, 0, 0, 0),
        )
    return warped, ok


def _remap(src4: U8, source: CameraModel, grid: _TargetGrid, T_t: F64, plane_z: float, flag: int) -> tuple[U8, Bool]:
    target = grid.model
    k, h, w = T_t.shape[0], target.height, target.width
    rays = grid.rays if grid.rays is not None else _unit_rays(target, grid.pixels)
    R_t = T_t[:, :3, :3]
    centre = -np.einsum("kji,kj->ki", R_t, T_t[:, :3, 3])  # (K, 3) camera centres in the rig frame
    dirs = rays[None] @ R_t  # (K, H·W, 3) rig-frame directions: d_rig = Rᵀ d_cam, as rows d_camᵀ R
    with np.errstate(divide="ignore", invalid="ignore"):
        lam = (plane_z - centre[:, None, 2]) / dirs[..., 2]
        ok = np.isfinite(lam) & (lam * rays[None, :, 2] > NEAR_Z)
    points = centre[:, None, :] + np.where(ok, lam, 0.0)[..., None] * dirs
    points[~ok] = 0.0
    uv, visible = source.project(points)  # distortion applied by the camera model itself
    ok &= visible
    uv = np.where(ok[..., None], uv, _OFF_IMAGE).astype(np.float32)
    map_x = np.ascontiguousarray(uv[..., 0].reshape(k * h, w))
    map_y = np.ascontiguousarray(uv[..., 1].reshape(k * h, w))
    warped = cv2.remap(src4, map_x, map_y, flag, borderMode=cv2.BORDER_CONSTANT, borderValue=(0, 0, 0, 0))
    return np.asarray(warped, dtype=np.uint8).reshape(k, h, w, 4), ok.reshape(k, h, w)


def _unit_rays(model: CameraModel, pixels: F64) -> F64:
    """Unit camera-frame rays of an undistorted camera's pixels (H·W, 3) (the remap path forced)."""
    return model.unproject(pixels[:2].T)


class SceneReprojector:
    """Γ⁺'s scene prior: ``reprojector(current_images, current_q14, future_q14, …) -> ReprojectionPrior``.

    ``cameras`` gives every view's model and pose for joint vectors; ``plane_z`` is the height of the
    plane in the rig frame (the table surface is 0); ``interpolation`` ``"linear"`` (images) or
    ``"nearest"`` (label maps; no colour matching); ``method`` as in :func:`warp_through_plane`. Wrist
    views fall back to the head view (:data:`~pilworld.types.HEAD_VIEW`) when ``cameras`` has it; with
    ``match_head_colour`` its pixels are first scaled per channel to the wrist camera's colours (the
    gain between the head view warped into the current wrist pose and the current wrist frame).
    """

    def __init__(
        self,
        cameras: RigCameras,
        plane_z: float = 0.0,
        *,
        interpolation: str = "linear",
        method: str = "auto",
        match_head_colour: bool = True,
        robot_margin: float = ROBOT_MARGIN,
    ) -> None:
        if isinstance(plane_z, bool) or not isinstance(plane_z, int | float) or not np.isfinite(plane_z):
            raise ValueError(f"plane_z: expected a finite height in metres, got {plane_z!r}")
        if interpolation not in _INTERPOLATIONS:
            raise ValueError(f"interpolation: expected one of {sorted(_INTERPOLATIONS)}, got {interpolation!r}")
        if method not in _METHODS:
            raise ValueError(f"method: expected one of {list(_METHODS)}, got {method!r}")
        self.cameras = cameras
        self.plane_z = float(plane_z)
        self.interpolation = interpolation
        self.method = method
        self.match_head_colour = bool(match_head_colour) and interpolation == "linear"
        if not (np.isfinite(robot_margin) and 0.0 <= robot_margin <= 0.25):
            raise ValueError(f"robot_margin: expected a fraction of the image size in [0, 0.25], got {robot_margin!r}")
        self.robot_margin = float(robot_margin)
        self._margin_kernel = {}
        for v in cameras.views:
            px = round(self.robot_margin * min(v.model.width, v.model.height))
            if px > 0:
                self._margin_kernel[v.name] = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (2 * px + 1, 2 * px + 1))
        self._flag = _INTERPOLATIONS[interpolation]
        self._grids = {v.name: _TargetGrid(v.model) for v in cameras.views}
        self._head: ViewCamera | None = next((v for v in cameras.views if v.name == HEAD_VIEW and not v.moves), None)
        self._remap_for = {
            (s.name, t.name): _use_remap(s.model, t.model, method)
            for t in cameras.views
            for s in cameras.views
            if t.moves and (s is t or s is self._head)
        }

    @property
    def views(self) -> tuple[str, ...]:
        return self.cameras.names

    def __call__(
        self,
        current_images: Mapping[str, U8],
        current_q14: NDArray[np.floating],
        future_q14: NDArray[np.floating],
        current_robot_masks: Mapping[str, Bool] | None = None,
        future_robot_masks: Mapping[str, Bool] | None = None,
    ) -> ReprojectionPrior:
        """The prior for the K future joint vectors ``future_q14`` (K, 14) from the current frame.

        ``current_images``: view → uint8 (H, W, 3) RGB at ``current_q14`` (14,). ``current_robot_masks``:
        view → bool (H, W), True on robot pixels of the current frame; ``future_robot_masks``: view →
        bool (K, H, W), True where the robot will be. Each None or with every view.
        """
        q_now = _joints(current_q14, "current_q14", 1)
        q_future = _joints(future_q14, "future_q14", 2)
        k = q_future.shape[0]
        images = _check_views("current_images", current_images, self.cameras, None, np.uint8)
        assert images is not None
        now_masks = _check_views("current_robot_masks", current_robot_masks, self.cameras, None, np.bool_)
        future_masks = _check_views("future_robot_masks", future_robot_masks, self.cameras, k, np.bool_)
        poses_now = self.cameras.poses(q_now)
        poses_future = self.cameras.poses(q_future)
        rgba = {
            v.name: _with_alpha(images[v.name], None if now_masks is None else ~now_masks[v.name])
            for v in self.cameras.views
        }

        out_images: dict[str, U8] = {}
        out_source: dict[str, U8] = {}
        for view in self.cameras.views:
            name = view.name
            h, w = view.model.height, view.model.width
            if not view.moves:
                # A static camera is its own future: the current frame without the robot.
                packed = np.broadcast_to(rgba[name].view(_PACKED)[..., 0], (k, h, w))
                own_ok = packed >= _ALPHA_FULL
                head_ok = None
            else:
                packed, own_ok = self._warp(rgba[name], view, poses_now[name], view, poses_future[name])
                head_ok = None
                if self._head is not None and not own_ok.all():
                    head = self._head
                    head_packed, head_ok = self._warp(
                        rgba[head.name], head, poses_now[head.name], view, poses_future[name]
                    )
                    head_ok &= ~own_ok
                    if self.match_head_colour:
                        head_packed = self._colour_matched(rgba, head, poses_now, view, head_packed)
                    packed = np.where(head_ok, head_packed, packed)
            source = own_ok.view(np.uint8).copy()  # SOURCE_OWN = 1 where the own view fills it
            if head_ok is not None:
                source += head_ok.view(np.uint8) * np.uint8(SOURCE_HEAD)
            if future_masks is not None:
                future = future_masks[name]
                kernel = self._margin_kernel.get(name)
                if kernel is not None:
                    # The robot's surroundings too: the render is least sure there (fingers stopped by a
                    # grasped object, servo residuals, a held object), and the world model paints them anyway.
                    future = np.stack([cv2.dilate(m.view(np.uint8), kernel) > 0 for m in future])
                source *= ~future
            packed = np.where(source != SOURCE_NONE, packed, np.uint32(0))
            out_images[name] = _unpack(packed)
            out_source[name] = source
        return ReprojectionPrior(images=out_images, source=out_source)

    def _colour_matched(
        self,
        rgba: dict[str, U8],
        head: ViewCamera,
        poses_now: dict[str, F64],
        view: ViewCamera,
        head_packed: NDArray[np.uint32],
    ) -> NDArray[np.uint32]:
        """``head_packed`` scaled per channel to the wrist camera's colours where both see the plane now.

        Two cameras render (or expose) the same table differently; the gain is the median ratio, per
        channel, over the pixels of the *current* wrist frame that the head view also fills.
        """
        head_now, ok = self._warp(rgba[head.name], head, poses_now[head.name], view, poses_now[view.name][None])
        own_now = rgba[view.name]
        ok &= own_now[..., 3] == _FULL
        n = int(ok.sum())
        if n < _MIN_MATCH_FRACTION * ok.size:
            return head_packed
        step = max(1, n // _MATCH_SAMPLES)
        head_rgb = head_now.view(np.uint8).reshape(*ok.shape[1:], 4)[ok[0], :3][::step].astype(np.float64)
        own_rgb = own_now[ok[0], :3][::step].astype(np.float64)
        # The median ratio: pixels where the plane assumption fails (objects) disagree and are outvoted.
        gain = np.clip(np.median((own_rgb + 1.0) / (head_rgb + 1.0), axis=0), *_GAIN_RANGE)
        k, h, w = head_packed.shape
        levels = np.arange(256, dtype=np.float64)[:, None]
        lut = np.clip(np.rint(levels * np.array([*gain.tolist(), 1.0])), 0, 255).astype(np.uint8)[None]  # (1, 256, 4)
        scaled = cv2.LUT(head_packed.view(np.uint8).reshape(k * h, w, 4), lut)
        out: NDArray[np.uint32] = np.asarray(scaled, dtype=np.uint8).reshape(k, h, w, 4).view(_PACKED)[..., 0]
        return out

    def _warp(
        self, src4: U8, source: ViewCamera, T_source: F64, target: ViewCamera, T_target: F64
    ) -> tuple[NDArray[np.uint32], Bool]:
        return _warp_rgba(
            src4,
            source.model,
            T_source,
            self._grids[target.name],
            T_target,
            self.plane_z,
            self._flag,
            self._remap_for[(source.name, target.name)],
        )


def _joints(value: NDArray[np.floating], name: str, ndim: int) -> F64:
    arr = np.asarray(value, dtype=np.float64)
    expected = f"({STATE_DIM},)" if ndim == 1 else f"(K, {STATE_DIM}) with K >= 1"
    if arr.ndim != ndim or arr.shape[-1] != STATE_DIM or arr.shape[0] == 0:
        raise ValueError(f"{name}: expected shape {expected}, got {arr.shape}")
    if not np.isfinite(arr).all():
        bad = tuple(int(i) for i in np.argwhere(~np.isfinite(arr))[0])
        raise ValueError(f"{name}: joint values must be finite, got {arr[bad]} at index {bad}")
    return arr


def _check_views(
    name: str, value: Mapping[str, NDArray[Any]] | None, cameras: RigCameras, frames: int | None, dtype: type
) -> dict[str, NDArray[Any]] | None:
    """``value`` with one array per view of ``cameras``, each of dtype and (frames,) H, W (, 3)."""
    if value is None:
        if name == "current_images":
            raise ValueError(f"{name}: expected a dict of every view {list(cameras.names)}, got None")
        return None
    if not isinstance(value, Mapping):
        raise ValueError(f"{name}: expected a dict view → array, got {type(value).__name__}")
    missing = [v for v in cameras.names if v not in value]
    if missing:
        raise ValueError(f"{name}: missing view(s) {missing} (views: {list(cameras.names)})")
    out: dict[str, NDArray[Any]] = {}
    for view in cameras.views:
        arr = np.asarray(value[view.name])
        shape: tuple[int, ...] = (view.model.height, view.model.width)
        shape = (*shape, 3) if dtype is np.uint8 else shape
        shape = shape if frames is None else (frames, *shape)
        if arr.dtype != dtype or arr.shape != shape:
            raise ValueError(
                f"{name}[{view.name!r}]: expected {np.dtype(dtype).name} {shape}, got {arr.dtype.name} {arr.shape}"
            )
        out[view.name] = arr
    return out
