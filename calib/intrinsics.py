"""Camera intrinsics from ChArUco detections, with the diagnostics that tell a good calibration from a bad one.

:func:`calibrate_intrinsics` runs ``cv2.calibrateCameraExtended`` on the object/image points of each view
(``CharucoBoard.matchImagePoints``) and reports:

* the RMS reprojection error overall and per view;
* parameter standard deviations (OpenCV's ``stdDeviationsIntrinsics``: the Gauss-Newton covariance scaled
  by the residual variance) and 95 % intervals ``value ± 1.96 σ``. They assume i.i.d. corner noise; a
  biased setup (a bent board, a rolling shutter) makes them too narrow;
* outlier views rejected iteratively: a view whose RMS exceeds ``median + k · 1.4826 · MAD`` (a robust
  ``k σ`` bound; the spread is floored at ``min_spread`` × median so that a set of equally good views
  never loses its slightly worst one) is dropped and the camera re-solved, until none is left;
* image coverage: the fraction of cells of a grid over the image that contain a used corner. Distortion
  is only known where corners were seen, so low coverage (< ~0.7) means the edges are extrapolated;
* a held-out error: a seeded subset of the inlier views is left out, the camera calibrated on the rest,
  and the held-out views' boards are posed with ``solvePnP`` using that camera; their reprojection RMS
  is what a new image would see. The returned camera itself is fit on *all* inlier views.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Any, Final

import cv2
import numpy as np
import numpy.typing as npt

from calib.camera_model import CameraModel
from calib.detect import Detection

__all__ = [
    "INTERVAL_Z",
    "CameraFit",
    "IntrinsicsOptions",
    "IntrinsicsResult",
    "ViewReport",
    "calibrate_intrinsics",
    "fit_camera",
]

FloatArray = npt.NDArray[np.float64]
IntArray = npt.NDArray[np.int64]

#: Two-sided 95 % normal quantile.
INTERVAL_Z: Final = 1.959963984540054
# Order of OpenCV's stdDeviationsIntrinsics.
_STD_NAMES: Final = ("fx", "fy", "cx", "cy", "k1", "k2", "p1", "p2", "k3", "k4", "k5", "k6", "s1", "s2", "s3", "s4")
_MAD_TO_SIGMA: Final = 1.4826  # MAD of a normal distribution times this is its σ


@dataclass(frozen=True)
class IntrinsicsOptions:
    """How to calibrate; validated on construction."""

    #: Distortion model: 4 (k1 k2 p1 p2), 5 (+ k3, OpenCV's default) or 8 (rational, wide-angle lenses).
    dist_coeffs: int = 5
    min_views: int = 4  #: fewer usable views than this raise ValueError
    min_corners_per_view: int = 6  #: views with fewer corners are skipped (a homography needs >= 4)
    outlier_k: float = 3.0  #: rejection threshold in robust σ above the median view RMS; inf disables
    min_spread: float = 0.1  #: floor of the robust σ as a fraction of the median view RMS
    max_rejection_rounds: int = 5
    held_out_fraction: float = 0.2  #: fraction of inlier views held out for the held-out error; 0 disables
    seed: int = 0  #: chooses the held-out views
    grid: tuple[int, int] = (8, 6)  #: coverage grid (columns, rows)

    def __post_init__(self) -> None:
        if self.dist_coeffs not in (4, 5, 8):
            raise ValueError(f"option 'dist_coeffs': expected 4, 5 or 8, got {self.dist_coeffs!r}")
        if self.min_views < 3:
            raise ValueError(f"option 'min_views': must be >= 3 (OpenCV needs 3 planar views), got {self.min_views}")
        if self.min_corners_per_view < 4:
            raise ValueError(f"option 'min_corners_per_view': must be >= 4, got {self.min_corners_per_view}")
        if not self.outlier_k > 0.0:
            raise ValueError(f"option 'outlier_k': must be > 0 (inf disables rejection), got {self.outlier_k}")
        if not 0.0 <= self.held_out_fraction < 1.0:
            raise ValueError(f"option 'held_out_fraction': must be in [0, 1), got {self.held_out_fraction}")
        if len(self.grid) != 2 or min(self.grid) < 1:
            raise ValueError(f"option 'grid': expected (columns, rows) >= 1, got {self.grid!r}")


@dataclass(frozen=True)
class ViewReport:
    """What happened to one input view."""

    name: str
    n_corners: int
    #: "used", "outlier" (rejected), "too_few_corners" or "collinear"
    status: str
    #: RMS reprojection error (px) under the final camera: from the calibration for used views, from a
    #: solvePnP pose for rejected ones; None if the view could not be posed.
    rms_px: float | None


@dataclass(frozen=True, eq=False)
class IntrinsicsResult:
    """A calibration and its diagnostics (see the module docstring)."""

    camera: CameraModel
    rms_px: float  #: over all corners of the used views
    views: tuple[ViewReport, ...]
    std: dict[str, float]  #: σ of fx, fy, cx, cy and the estimated distortion coefficients
    intervals95: dict[str, tuple[float, float]]  #: value ± 1.96 σ, same keys as ``std``
    coverage: float  #: fraction of grid cells with at least one used corner
    coverage_grid: IntArray = field(repr=False)  #: ``(rows, cols)`` corner counts per cell
    held_out_rms_px: float | None  #: None if too few views to hold any out
    held_out_views: tuple[str, ...]
    rejection_rounds: int

    @property
    def n_used(self) -> int:
        return sum(v.status == "used" for v in self.views)

    def value(self, name: str) -> float:
        """Estimated value of a parameter named as in :attr:`std` (``fx``, ``cy``, ``k1``, ...)."""
        K, d = self.camera.K, self.camera.dist
        fixed = {"fx": K[0, 0], "fy": K[1, 1], "cx": K[0, 2], "cy": K[1, 2]}
        if name in fixed:
            return float(fixed[name])
        return float(d[_STD_NAMES.index(name) - 4])

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready summary."""
        return {
            "camera": self.camera.to_dict(),
            "rms_px": self.rms_px,
            "n_views_used": self.n_used,
            "views": [
                {"name": v.name, "n_corners": v.n_corners, "status": v.status, "rms_px": v.rms_px} for v in self.views
            ],
            "std": self.std,
            "intervals95": {k: list(v) for k, v in self.intervals95.items()},
            "coverage": self.coverage,
            "coverage_grid": self.coverage_grid.tolist(),
            "held_out_rms_px": self.held_out_rms_px,
            "held_out_views": list(self.held_out_views),
            "rejection_rounds": self.rejection_rounds,
        }


@dataclass(frozen=True)
class CameraFit:
    K: FloatArray
    dist: FloatArray
    rms: float
    per_view: FloatArray
    std: FloatArray


def _flags(n_dist: int) -> int:
    if n_dist == 4:
        return int(cv2.CALIB_FIX_K3)
    if n_dist == 8:
        return int(cv2.CALIB_RATIONAL_MODEL)
    return 0


def fit_camera(
    obj: Sequence[FloatArray], img: Sequence[FloatArray], size: tuple[int, int], n_dist: int = 5
) -> CameraFit:
    """One ``cv2.calibrateCameraExtended`` over the views' object/image points (``cv2.error`` when degenerate)."""
    rms, K, dist, _, _, std, _, per_view = cv2.calibrateCameraExtended(
        [o.astype(np.float32).reshape(-1, 1, 3) for o in obj],
        [i.astype(np.float32).reshape(-1, 1, 2) for i in img],
        size,
        np.eye(3),  # ignored: without CALIB_USE_INTRINSIC_GUESS OpenCV initialises K itself
        np.zeros((1, 8 if n_dist == 8 else 5)),
        flags=_flags(n_dist),
    )
    return CameraFit(
        K=np.asarray(K, np.float64),
        dist=np.asarray(dist, np.float64).reshape(-1)[:n_dist],
        rms=float(rms),
        per_view=np.asarray(per_view, np.float64).reshape(-1),
        std=np.asarray(std, np.float64).reshape(-1),
    )


def _pnp_rms(obj: FloatArray, img: FloatArray, K: FloatArray, dist: FloatArray) -> tuple[float, float] | None:
    """(sum of squared errors, RMS) of the best pose of one planar view, or None if it cannot be posed."""
    ok, rvec, tvec = cv2.solvePnP(obj, img, K, dist, flags=cv2.SOLVEPNP_IPPE)
    if not ok:
        return None
    rvec, tvec = cv2.solvePnPRefineLM(obj, img, K, dist, rvec, tvec)
    proj, _ = cv2.projectPoints(obj, rvec, tvec, K, dist)
    sq = float(((proj.reshape(-1, 2) - img) ** 2).sum())
    return sq, math.sqrt(sq / img.shape[0])


def _coverage(points: Sequence[FloatArray], size: tuple[int, int], grid: tuple[int, int]) -> IntArray:
    cols, rows = grid
    counts = np.zeros((rows, cols), dtype=np.int64)
    if points:
        uv = np.concatenate(points)
        c = np.clip(((uv[:, 0] + 0.5) / size[0] * cols).astype(np.int64), 0, cols - 1)
        r = np.clip(((uv[:, 1] + 0.5) / size[1] * rows).astype(np.int64), 0, rows - 1)
        np.add.at(counts, (r, c), 1)
    return counts


def calibrate_intrinsics(
    detections: Sequence[Detection],
    options: IntrinsicsOptions | None = None,
    T_cam_base: npt.ArrayLike | None = None,
    name: str = "cam_high",
) -> IntrinsicsResult:
    """Calibrate K and distortion from the detections of one camera (see the module docstring).

    ``T_cam_base`` (identity if not given) is only stored in the returned :class:`CameraModel`; the
    hand-eye calibration provides it. Raises ``ValueError`` naming the cause if the images differ in
    size or fewer than ``options.min_views`` views have enough (non-collinear) corners.
    """
    opt = options if options is not None else IntrinsicsOptions()
    if not detections:
        raise ValueError("calibrate_intrinsics: no detections given (no images, or none could be read)")
    sizes = {d.image_size for d in detections}
    if len(sizes) != 1:
        raise ValueError(f"calibrate_intrinsics: all images must have the same size, got {sorted(sizes)}")
    size = detections[0].image_size

    status: dict[int, str] = {}
    points: dict[int, tuple[FloatArray, FloatArray]] = {}
    for i, det in enumerate(detections):
        if det.n_corners < opt.min_corners_per_view:
            status[i] = "too_few_corners"
            continue
        obj, img = det.object_image_points()
        # Corners on one line (a single row of the board) give no homography: calibrateCamera would fail.
        if np.linalg.matrix_rank(obj[:, :2] - obj[:, :2].mean(0), tol=1e-9) < 2:
            status[i] = "collinear"
            continue
        status[i] = "used"
        points[i] = (obj, img)
    usable = sorted(points)
    if len(usable) < opt.min_views:
        few = sum(s == "too_few_corners" for s in status.values())
        raise ValueError(
            f"calibrate_intrinsics: only {len(usable)} of {len(detections)} views are usable, need >= {opt.min_views} "
            f"({few} had fewer than {opt.min_corners_per_view} corners, "
            f"{sum(s == 'collinear' for s in status.values())} had collinear corners); take more images with "
            "the whole board visible"
        )

    def fit(ids: Sequence[int]) -> CameraFit:
        return fit_camera([points[i][0] for i in ids], [points[i][1] for i in ids], size, opt.dist_coeffs)

    used = list(usable)
    result = fit(used)
    rounds = 0
    while math.isfinite(opt.outlier_k) and rounds < opt.max_rejection_rounds:
        med = float(np.median(result.per_view))
        spread = max(_MAD_TO_SIGMA * float(np.median(np.abs(result.per_view - med))), opt.min_spread * med)
        bad = {used[j] for j, e in enumerate(result.per_view) if e > med + opt.outlier_k * spread}
        if not bad or len(used) - len(bad) < opt.min_views:
            break
        for i in bad:
            status[i] = "outlier"
        used = [i for i in used if i not in bad]
        result = fit(used)
        rounds += 1

    K, dist = result.K, result.dist
    view_rms: dict[int, float | None] = dict(zip(used, (float(e) for e in result.per_view), strict=True))
    for i in usable:
        if i not in view_rms:
            pnp = _pnp_rms(*points[i], K, dist)
            view_rms[i] = None if pnp is None else pnp[1]

    names = _STD_NAMES[: 4 + opt.dist_coeffs]
    values = [K[0, 0], K[1, 1], K[0, 2], K[1, 2], *dist]
    std = {n: float(result.std[j]) for j, n in enumerate(names)}
    intervals = {
        n: (float(values[j]) - INTERVAL_Z * std[n], float(values[j]) + INTERVAL_Z * std[n]) for j, n in enumerate(names)
    }

    held_out_rms, held = _held_out(used, points, opt, fit)
    grid = _coverage([points[i][1] for i in used], size, opt.grid)
    camera = CameraModel(
        K=K,
        dist=dist,
        T_cam_base=np.eye(4) if T_cam_base is None else np.asarray(T_cam_base, dtype=np.float64),
        width=size[0],
        height=size[1],
        name=name,
    )
    return IntrinsicsResult(
        camera=camera,
        rms_px=result.rms,
        views=tuple(ViewReport(d.name, d.n_corners, status[i], view_rms.get(i)) for i, d in enumerate(detections)),
        std=std,
        intervals95=intervals,
        coverage=float((grid > 0).mean()),
        coverage_grid=grid,
        held_out_rms_px=held_out_rms,
        held_out_views=tuple(detections[i].name for i in held),
        rejection_rounds=rounds,
    )


def _held_out(
    used: list[int],
    points: dict[int, tuple[FloatArray, FloatArray]],
    opt: IntrinsicsOptions,
    fit: Callable[[Sequence[int]], CameraFit],
) -> tuple[float | None, list[int]]:
    n_hold = round(opt.held_out_fraction * len(used))
    if opt.held_out_fraction > 0.0:
        n_hold = max(n_hold, 1)
    if n_hold == 0 or len(used) - n_hold < opt.min_views:
        return None, []
    rng = np.random.default_rng(opt.seed)
    held = sorted(int(i) for i in rng.choice(used, size=n_hold, replace=False))
    train = [i for i in used if i not in held]
    sub = fit(train)
    total_sq, total_n = 0.0, 0
    for i in held:
        pnp = _pnp_rms(*points[i], sub.K, sub.dist)
        if pnp is None:
            continue
        total_sq += pnp[0]
        total_n += points[i][1].shape[0]
    return (math.sqrt(total_sq / total_n) if total_n else None), held
