"""Synthetic ChArUco images seen by a known camera: ground truth for the calibration tests and benchmarks.

Method (all seeded):

1. **Poses.** The board is placed in front of the camera with a random tilt (5-60° by default, about a
   random in-plane axis), a random roll about its normal, a random depth and a random image position,
   and kept only if every outer corner of the board projects inside the image with a margin (so views
   also reach the image corners, where distortion is observable).
2. **Rendering.** Each output pixel (at ``supersample`` x the resolution) is undistorted once per camera
   to its normalized ray with :meth:`CameraModel.unproject` (the exact inverse of the true projection,
   including distortion), intersected with the board plane through the homography ``[r1 r2 t]⁻¹``, and
   looked up with ``cv2.remap`` in an area-antialiased texture of the board. The texture resolution is
   chosen per view so the texture is never minified (no aliasing). The result is averaged down to the
   camera resolution (``INTER_AREA``), blurred slightly (optics) and given a little intensity noise.
3. **Pixel noise.** How image noise turns into corner noise depends on contrast, blur and the detector,
   so the calibration noise level is set explicitly instead: :func:`perturb_detection` adds i.i.d.
   Gaussian noise of ``sigma`` pixels to each coordinate of every *detected* corner (so σ = 0.3 px gives
   a per-corner RMS of 0.3·√2 ≈ 0.42 px, which is what OpenCV's RMS reports). The detector's own error
   on these renders is small (below), so the corners carry ≈ ``sigma`` px of i.i.d. noise per
   coordinate, as the solver's statistics assume.

The detector's own error on these renders is ~0.04 px RMS for boards seen at moderate angles, but grows
to 0.1-0.4 px on steep (50-60°) views where squares shrink below ~10 px and ``cornerSubPix`` windows
reach the markers: the same happens with real images, and such views are what the outlier rejection of
:mod:`calib.intrinsics` sometimes drops. Noise-free renders therefore still leave ~0.1 % bias in f.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from functools import lru_cache

import cv2
import numpy as np
import numpy.typing as npt

from calib.board import ChArUcoBoard
from calib.camera_model import CameraModel
from calib.detect import Detection

__all__ = ["SyntheticView", "perturb_detection", "random_board_pose", "render_view", "synthetic_views"]

FloatArray = npt.NDArray[np.float64]
UInt8Array = npt.NDArray[np.uint8]

_BACKGROUND = 110.0  # grey, so the board's white quiet zone stands out as on a real desk


@dataclass(frozen=True, eq=False)
class SyntheticView:
    """One rendered view with its ground truth."""

    image: UInt8Array  #: ``(H, W)`` grayscale
    T_cam_board: FloatArray  #: ``(4, 4)`` maps board-frame points (metres) into the camera frame
    corners_true: FloatArray  #: ``(n_corners, 2)`` true pixels of all chessboard corners, row = corner id


def _outline(board: ChArUcoBoard) -> FloatArray:
    w, h = board.size_m
    return np.array([[0.0, 0.0, 0.0], [w, 0.0, 0.0], [w, h, 0.0], [0.0, h, 0.0]])


def random_board_pose(
    board: ChArUcoBoard,
    camera: CameraModel,
    rng: np.random.Generator,
    fill: tuple[float, float] = (0.5, 0.9),
    max_tilt_deg: float = 60.0,
    max_roll_deg: float = 30.0,
    margin_px: float = 8.0,
) -> FloatArray:
    """A random ``T_cam_board`` (4x4) with the whole board in the image.

    The board's width covers a ``fill`` fraction of the image width (this sets the depth); the tilt is
    uniform in ``[5°, max_tilt_deg]`` (some tilt is needed to observe the focal length).
    """
    fx = float(camera.K[0, 0])
    w_m, h_m = board.size_m
    center_b = np.array([w_m / 2.0, h_m / 2.0, 0.0])
    outline = _outline(board)
    for _ in range(2000):
        depth = fx * w_m / (rng.uniform(*fill) * camera.width)
        axis_angle = rng.uniform(0.0, 2.0 * math.pi)
        tilt = math.radians(rng.uniform(5.0, max_tilt_deg))
        tilt_vec = tilt * np.array([math.cos(axis_angle), math.sin(axis_angle), 0.0])
        R_tilt, _ = cv2.Rodrigues(tilt_vec)
        R_roll, _ = cv2.Rodrigues(np.array([0.0, 0.0, math.radians(rng.uniform(-max_roll_deg, max_roll_deg))]))
        R = R_tilt @ R_roll
        u, v = rng.uniform(0.0, camera.width - 1.0), rng.uniform(0.0, camera.height - 1.0)
        ray = camera.unproject(np.array([u, v]))
        if not np.all(np.isfinite(ray)):
            continue
        center_c = ray / ray[2] * depth
        T = np.eye(4)
        T[:3, :3] = R
        T[:3, 3] = center_c - R @ center_b
        proj = camera.with_pose(T).project_detailed(outline)
        uv = proj.uv
        inside = (
            proj.in_valid_fov.all()
            and (uv[:, 0] >= margin_px).all()
            and (uv[:, 0] <= camera.width - 1 - margin_px).all()
            and (uv[:, 1] >= margin_px).all()
            and (uv[:, 1] <= camera.height - 1 - margin_px).all()
        )
        if inside:
            return T
    raise ValueError(
        f"random_board_pose: could not fit a {w_m:.3f} x {h_m:.3f} m board into the {camera.width}x{camera.height} "
        f"image with fill {fill}; lower fill or the tilt"
    )


@lru_cache(maxsize=4)
def _normalized_grid(camera: CameraModel, supersample: int) -> tuple[FloatArray, FloatArray]:
    """Undistorted normalized coordinates ``x, y`` ``(H s, W s)`` of the supersampled pixel centres.

    Undistorting ~1 M pixels costs a few hundred ms, and the grid depends only on the camera, so it is
    computed once per camera and shared by all views (the model is immutable and hashable).
    """
    s = supersample
    us = (np.arange(camera.width * s) + 0.5) / s - 0.5
    vs = (np.arange(camera.height * s) + 0.5) / s - 0.5
    uu, vv = np.meshgrid(us, vs)
    rays = camera.with_pose(np.eye(4)).unproject(np.stack([uu, vv], axis=-1))
    with np.errstate(invalid="ignore", divide="ignore"):
        x = rays[..., 0] / rays[..., 2]
        y = rays[..., 1] / rays[..., 2]
    return x, y


def render_view(
    board: ChArUcoBoard,
    camera: CameraModel,
    T_cam_board: npt.ArrayLike,
    rng: np.random.Generator | None = None,
    supersample: int = 2,
    blur_sigma_px: float = 0.5,
    noise_gray: float = 1.0,
) -> UInt8Array:
    """Render ``board`` at ``T_cam_board`` through ``camera`` (its K and distortion) as a uint8 gray image."""
    if isinstance(supersample, bool) or not isinstance(supersample, int) or not 1 <= supersample <= 8:
        raise ValueError(f"supersample must be an integer in 1..8, got {supersample!r}")
    T = np.asarray(T_cam_board, dtype=np.float64)
    R, t = T[:3, :3], T[:3, 3]
    x, y = _normalized_grid(camera, supersample)
    # Board point (bx, by, 0) maps to normalized image coordinates through H = [r1 r2 t].
    H_inv = np.linalg.inv(np.column_stack([R[:, 0], R[:, 1], t]))
    with np.errstate(invalid="ignore", divide="ignore"):
        bw = H_inv[2, 0] * x + H_inv[2, 1] * y + H_inv[2, 2]
        bx = (H_inv[0, 0] * x + H_inv[0, 1] * y + H_inv[0, 2]) / bw
        by = (H_inv[1, 0] * x + H_inv[1, 1] * y + H_inv[1, 2]) / bw
        # Depth along the ray at the hit, sign only: hits behind the camera are not seen.
        depth_sign = (R[2, 0] * bx + R[2, 1] * by + t[2]) > 0.0
    valid = np.isfinite(bx) & np.isfinite(by) & depth_sign
    # Texture resolution ≈ the lowest sampling density over the board, so bilinear lookup only magnifies.
    depth_far = float((_outline(board) @ R.T + t)[:, 2].max())
    cos_tilt = max(abs(float(R[2, 2])), 0.3)
    ppm = max(200.0, supersample * float(min(camera.K[0, 0], camera.K[1, 1])) * cos_tilt / depth_far)
    margin = max(board.margin_m, 0.5 * board.square_length_m)
    texture = board.render(ppm, antialias=True, margin_m=margin).astype(np.float32)
    map_x = np.where(valid, (bx + margin) * ppm - 0.5, -1e6).astype(np.float32)
    map_y = np.where(valid, (by + margin) * ppm - 0.5, -1e6).astype(np.float32)
    big = cv2.remap(texture, map_x, map_y, cv2.INTER_LINEAR, borderMode=cv2.BORDER_CONSTANT, borderValue=(_BACKGROUND,))
    img = np.asarray(cv2.resize(big, (camera.width, camera.height), interpolation=cv2.INTER_AREA), np.float32)
    if blur_sigma_px > 0.0:
        img = np.asarray(cv2.GaussianBlur(img, (0, 0), blur_sigma_px), np.float32)
    if noise_gray > 0.0:
        gen = rng if rng is not None else np.random.default_rng(0)
        img = img + gen.normal(0.0, noise_gray, size=img.shape).astype(np.float32)
    return np.asarray(np.clip(np.round(img), 0, 255), dtype=np.uint8)


def synthetic_views(
    board: ChArUcoBoard,
    camera: CameraModel,
    n_views: int,
    seed: int,
    supersample: int = 2,
    blur_sigma_px: float = 0.5,
    noise_gray: float = 1.0,
) -> list[SyntheticView]:
    """``n_views`` random views of ``board`` through ``camera``, reproducible from ``seed``."""
    if n_views < 1:
        raise ValueError(f"n_views must be >= 1, got {n_views}")
    rng = np.random.default_rng(seed)
    corners3d = board.corner_points()
    views = []
    for _ in range(n_views):
        T = random_board_pose(board, camera, rng)
        image = render_view(board, camera, T, rng, supersample, blur_sigma_px, noise_gray)
        uv, _ = camera.with_pose(T).project(corners3d)
        views.append(SyntheticView(image=image, T_cam_board=T, corners_true=uv))
    return views


def perturb_detection(detection: Detection, sigma_px: float, rng: np.random.Generator) -> Detection:
    """``detection`` with i.i.d. Gaussian noise of ``sigma_px`` added to each corner coordinate."""
    if not (math.isfinite(sigma_px) and sigma_px >= 0.0):
        raise ValueError(f"sigma_px must be a finite number >= 0, got {sigma_px!r}")
    return detection.with_corners(detection.corners + rng.normal(0.0, sigma_px, detection.corners.shape))
