"""Intrinsics from a live camera: keep the frames that add something, stop at the targets, solve.

``pilworld calibrate intrinsics --live`` grabs full-resolution frames from a rig's camera (the same
``OpenCVCamera`` driver a paired run uses) while someone moves the board in front of it. Most frames
repeat what is known already — the board held still, or shown again where it was — so each detection is
*offered* to a :class:`ViewSelector`, which keeps it only when it

* shows at least ``min_corners`` corners, and is not a near-duplicate of a kept view (the same corners
  within ``duplicate_px`` on average: a board held still), and
* **adds coverage** (puts a corner in a cell of the coverage grid that had none — distortion is only known
  where corners were seen), or **adds tilt** (the board's face is tilted at least ``tilt_deg`` off the line
  of sight towards a side no kept view has covered yet: tilted views are what pin the focal length down),
  or, while a target is still missing, is simply a distinct view (more corners, less noise).

After every kept view (from the fourth on) the camera is re-solved with ``cv2.calibrateCamera`` for the
running RMS and the principal point's σ, and tilts are measured with the current estimate.
:class:`LiveTargets` says when to stop: coverage, view count, tilted views, RMS and principal-point σ all
reached (or ``max_views``, a time limit, or Enter). The kept
frames are saved as PNG as they are kept (``NNN.png``), so an interrupted collection loses nothing and
``--resume`` continues from them; the final solve is :func:`calib.intrinsics.calibrate_intrinsics`, as for a
folder of images.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Final

import cv2
import numpy as np
import numpy.typing as npt

from calib.detect import BoardDetector, Detection
from calib.intrinsics import fit_camera

__all__ = ["LiveTargets", "Offer", "ViewSelector", "collect_live", "coverage_lines", "load_views"]

FloatArray = npt.NDArray[np.float64]
IntArray = npt.NDArray[np.int64]
Image = npt.NDArray[np.uint8]

#: Tilt directions are binned into this many sectors around the line of sight.
TILT_SECTORS: Final = 4
VIEW_GLOB: Final = "[0-9][0-9][0-9].png"


@dataclass(frozen=True)
class LiveTargets:
    """When a live collection is complete; validated on construction."""

    coverage: float = 0.8  #: fraction of the coverage grid's cells with a corner
    views: int = 20  #: at least this many kept views
    max_views: int = 60  #: stop when this many are kept, whatever else holds
    rms_px: float = 0.5  #: running reprojection RMS at most this
    #: the principal point's σ (OpenCV's, from the running solve) at most this: it is what moves ``T_cam_base``
    #: most (a 3 px error at 1024² costs ~3 mm, docs/calibration.md) and what tilted views near the edges pin down
    pp_sigma_px: float = 0.6
    tilted_views: int = 4  #: kept views tilted at least ``tilt_deg`` …
    tilt_deg: float = 20.0  #: … off the line of sight (one per side of TILT_SECTORS at most counts)
    max_seconds: float = 900.0  #: give up waiting for new views after this long

    def __post_init__(self) -> None:
        if not 0.0 < self.coverage <= 1.0:
            raise ValueError(f"coverage target: expected a fraction in (0, 1], got {self.coverage}")
        if self.views < 4:
            raise ValueError(f"views target: expected at least 4 views (a calibration needs them), got {self.views}")
        if self.max_views < self.views:
            raise ValueError(f"max views: expected at least the views target {self.views}, got {self.max_views}")
        if not self.rms_px > 0.0:
            raise ValueError(f"RMS target: expected pixels > 0, got {self.rms_px}")
        if not self.pp_sigma_px > 0.0:
            raise ValueError(f"principal-point σ target: expected pixels > 0, got {self.pp_sigma_px}")
        if self.tilted_views < 0 or not 0.0 <= self.tilt_deg < 80.0:
            raise ValueError(f"tilt target: expected >= 0 views at 0-80°, got {self.tilted_views} at {self.tilt_deg}°")
        if not self.max_seconds > 0.0:
            raise ValueError(f"time limit: expected seconds > 0, got {self.max_seconds}")


@dataclass(frozen=True)
class Offer:
    """What the selector made of one detection."""

    kept: bool
    reason: str  #: e.g. "adds coverage (+3 cells)", "near-duplicate of view 4", "5 corners (< 12)"
    tilt_deg: float | None = None


@dataclass
class ViewSelector:
    """Keeps the detections that add coverage or tilt (see the module docstring); the running solve."""

    image_size: tuple[int, int]  #: (width, height) of the frames
    K_guess: FloatArray  #: a rough camera matrix, for tilts until the first solve
    targets: LiveTargets = field(default_factory=LiveTargets)
    grid: tuple[int, int] = (8, 6)  #: coverage grid (columns, rows), as calib.intrinsics reports it
    min_corners: int = 12
    duplicate_px: float = 0.02  #: as a fraction of the image width
    views: list[Detection] = field(default_factory=list)
    tilts: list[float] = field(default_factory=list)
    sectors: set[int] = field(default_factory=set)  #: tilt directions covered by views tilted >= tilt_deg
    rms_px: float | None = None
    pp_sigma_px: float | None = None  #: the larger of σ(cx) and σ(cy) of the running solve
    K: FloatArray | None = None
    dist: FloatArray | None = None

    def __post_init__(self) -> None:
        cols, rows = self.grid
        self.counts: IntArray = np.zeros((rows, cols), dtype=np.int64)
        self.K_guess = np.asarray(self.K_guess, dtype=np.float64).reshape(3, 3)

    # ------------------------------------------------------------------ state

    @property
    def coverage(self) -> float:
        return float((self.counts > 0).mean())

    @property
    def tilted(self) -> int:
        return sum(t >= self.targets.tilt_deg for t in self.tilts)

    def missing(self) -> list[str]:
        """What the targets still lack (empty: done)."""
        t = self.targets
        out = []
        if len(self.views) < t.views:
            out.append(f"views {len(self.views)}/{t.views}")
        if self.coverage < t.coverage:
            out.append(f"coverage {self.coverage:.0%}/{t.coverage:.0%}")
        if self.tilted < t.tilted_views:
            out.append(f"tilted views {self.tilted}/{t.tilted_views} (>= {t.tilt_deg:.0f}°)")
        if self.rms_px is None or self.rms_px > t.rms_px:
            rms = "n/a" if self.rms_px is None else f"{self.rms_px:.2f}"
            out.append(f"RMS {rms}/{t.rms_px} px")
        if self.pp_sigma_px is None or self.pp_sigma_px > t.pp_sigma_px:
            sigma = "n/a" if self.pp_sigma_px is None else f"{self.pp_sigma_px:.2f}"
            out.append(f"principal point σ {sigma}/{t.pp_sigma_px} px (tilted views near the edges)")
        return out

    def _cells(self, corners: FloatArray) -> IntArray:
        cols, rows = self.grid
        w, h = self.image_size
        c = np.clip(((corners[:, 0] + 0.5) / w * cols).astype(np.int64), 0, cols - 1)
        r = np.clip(((corners[:, 1] + 0.5) / h * rows).astype(np.int64), 0, rows - 1)
        return np.stack([r, c], axis=1)

    def _tilt(self, det: Detection) -> tuple[float, int] | None:
        """(tilt off the line of sight in degrees, direction sector) of the board, with the current camera."""
        obj, img = det.object_image_points()
        K = self.K if self.K is not None else self.K_guess
        dist = self.dist if self.dist is not None else np.zeros(5)
        ok, rvec, tvec = cv2.solvePnP(obj, img, K, dist, flags=cv2.SOLVEPNP_IPPE)
        if not ok:
            return None
        R, _ = cv2.Rodrigues(rvec)
        normal = R[:, 2]  # board z, into the board, camera frame
        centre = R @ obj.mean(axis=0) + np.asarray(tvec).reshape(3)
        sight = centre / np.linalg.norm(centre)
        tilt = math.degrees(math.acos(min(1.0, abs(float(normal @ sight)))))
        # Direction of the tilt: the normal's component across the line of sight, in image axes.
        across = normal - (normal @ sight) * sight
        angle = math.atan2(float(across[1]), float(across[0])) % (2 * math.pi)
        return tilt, int(angle / (2 * math.pi / TILT_SECTORS)) % TILT_SECTORS

    # ------------------------------------------------------------------ offers

    def offer(self, det: Detection) -> Offer:
        """Keep ``det`` if it adds coverage or tilt; refreshes the running solve when it does."""
        if det.image_size != tuple(self.image_size):
            raise ValueError(f"frame size {det.image_size} differs from the first frames' {self.image_size}")
        if len(self.views) >= self.targets.max_views:
            return Offer(False, f"{self.targets.max_views} views kept already")
        if det.n_corners < self.min_corners:
            return Offer(False, f"{det.n_corners} corners (< {self.min_corners})")
        limit = self.duplicate_px * self.image_size[0]
        for i, v in enumerate(self.views):
            common, a, b = np.intersect1d(v.corner_ids, det.corner_ids, return_indices=True)
            close = common.size and float(np.linalg.norm(v.corners[a] - det.corners[b], axis=1).mean()) < limit
            if common.size >= 0.5 * det.n_corners and close:
                return Offer(False, f"near-duplicate of view {i}")
        tilt = self._tilt(det)
        cells = self._cells(det.corners)
        new = {(int(r), int(c)) for r, c in cells if self.counts[r, c] == 0}
        tilt_deg = None if tilt is None else tilt[0]
        reason = ""
        if new:
            reason = f"adds coverage (+{len(new)} cell{'s' if len(new) > 1 else ''})"
        elif tilt is not None and tilt[0] >= self.targets.tilt_deg and tilt[1] not in self.sectors:
            reason = f"adds tilt ({tilt[0]:.0f}° towards a new side)"
        elif self.missing():
            # Until every target holds, any distinct view helps the solve (more corners, less noise).
            reason = "a distinct view"
        if not reason:
            return Offer(False, "adds nothing new", tilt_deg)
        self._keep(det, cells, tilt)
        return Offer(True, reason, tilt_deg)

    def restore(self, detections: list[Detection]) -> None:
        """Keep the views an interrupted collection saved (``--resume``) without judging them again; one solve."""
        for det in detections:
            if det.image_size != tuple(self.image_size):
                raise ValueError(f"saved view {det.name}: {det.image_size} frames, the camera sends {self.image_size}")
            self._keep(det, self._cells(det.corners), self._tilt(det), solve=False)
        if len(self.views) >= 4:
            self._solve()

    def _keep(self, det: Detection, cells: IntArray, tilt: tuple[float, int] | None, *, solve: bool = True) -> None:
        self.views.append(det)
        np.add.at(self.counts, (cells[:, 0], cells[:, 1]), 1)
        self.tilts.append(0.0 if tilt is None else tilt[0])
        if tilt is not None and tilt[0] >= self.targets.tilt_deg:
            self.sectors.add(tilt[1])
        if solve and len(self.views) >= 4:
            self._solve()

    def _solve(self) -> None:
        pts = [v.object_image_points() for v in self.views]
        try:
            fit = fit_camera([o for o, _ in pts], [i for _, i in pts], self.image_size)
        except cv2.error:  # degenerate so far (e.g. all views parallel): keep collecting
            return
        self.rms_px, self.K, self.dist = fit.rms, fit.K, fit.dist
        self.pp_sigma_px = float(max(fit.std[2], fit.std[3])) if np.all(np.isfinite(fit.std[2:4])) else None
        # Re-measure the tilts with the better camera.
        self.sectors.clear()
        for i, v in enumerate(self.views):
            t = self._tilt(v)
            self.tilts[i] = 0.0 if t is None else t[0]
            if t is not None and t[0] >= self.targets.tilt_deg:
                self.sectors.add(t[1])


def coverage_lines(selector: ViewSelector) -> list[str]:
    """The coverage grid as text rows ('#' a cell with corners, '.' one without)."""
    return [" ".join("#" if c else "." for c in row) for row in selector.counts]


def status_lines(selector: ViewSelector, elapsed: float, last: str) -> list[str]:
    """The running display: counts, RMS, what is missing, the coverage map and the last decision."""
    rms = "n/a" if selector.rms_px is None else f"{selector.rms_px:.3f} px"
    sigma = "n/a" if selector.pp_sigma_px is None else f"{selector.pp_sigma_px:.2f} px"
    missing = selector.missing()
    head = (
        f"views {len(selector.views)}  coverage {selector.coverage:.0%}  tilted {selector.tilted}  RMS {rms}  "
        f"principal point σ {sigma}  {elapsed:.0f} s"
    )
    todo = "targets reached" if not missing else "still needed: " + ", ".join(missing)
    return [head, todo, *("  " + row for row in coverage_lines(selector)), f"last frame: {last}"]


def write_preview(path: Path, image: Image, selector: ViewSelector, det: Detection | None) -> None:
    """The latest frame with its corners, the coverage grid shaded and the counts; written atomically."""
    bgr = cv2.cvtColor(np.asarray(image, dtype=np.uint8), cv2.COLOR_RGB2BGR) if image.ndim == 3 else image
    bgr = cv2.cvtColor(bgr, cv2.COLOR_GRAY2BGR) if bgr.ndim == 2 else bgr.copy()
    h, w = bgr.shape[:2]
    rows, cols = selector.counts.shape
    shade = bgr.copy()
    for r in range(rows):
        for c in range(cols):
            if selector.counts[r, c] == 0:
                x0, y0 = c * w // cols, r * h // rows
                cv2.rectangle(shade, (x0, y0), ((c + 1) * w // cols - 1, (r + 1) * h // rows - 1), (0, 0, 160), -1)
    bgr = cv2.addWeighted(shade, 0.3, bgr, 0.7, 0.0)
    if det is not None:
        for u, v in det.corners:
            cv2.circle(bgr, (round(u), round(v)), max(2, w // 200), (0, 220, 0), -1)
    rms = "n/a" if selector.rms_px is None else f"{selector.rms_px:.2f}px"
    text = f"views {len(selector.views)} cov {selector.coverage:.0%} tilted {selector.tilted} rms {rms}"
    cv2.putText(bgr, text, (8, max(20, h // 30)), cv2.FONT_HERSHEY_SIMPLEX, max(0.5, w / 1400), (255, 255, 255), 2)
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(path.name + ".tmp.png")
    cv2.imwrite(str(tmp), bgr)
    tmp.replace(path)


def load_views(folder: Path, detector: BoardDetector) -> list[tuple[str, Image, Detection]]:
    """The views an earlier (interrupted) collection saved in ``folder``: (file name, image, detection)."""
    out = []
    for path in sorted(folder.glob(VIEW_GLOB)):
        image = cv2.imread(str(path), cv2.IMREAD_GRAYSCALE)
        if image is None:
            raise ValueError(f"--resume: cannot read {path} as an image")
        img = np.asarray(image, dtype=np.uint8)
        out.append((path.name, img, detector.detect(img, name=path.name)))
    return out


@dataclass(frozen=True)
class LiveResult:
    views: tuple[Path, ...]  #: the saved frames, in the order kept
    stop: str  #: why the collection ended
    seconds: float
    frames_seen: int


def collect_live(
    grab: Callable[[], tuple[Image, int]],
    selector: ViewSelector,
    detector: BoardDetector,
    save: Path,
    *,
    stop_requested: Callable[[], str | None] = lambda: None,
    show: Callable[[list[str]], None] | None = None,
    preview: Path | None = None,
    clock: Callable[[], float] = time.monotonic,
) -> LiveResult:
    """Offer every new frame of ``grab`` (RGB or gray image, frame index) to ``selector`` until it is done.

    Each kept frame is written to ``save/NNN.png`` at once (after the views already there, which a resumed
    collection has offered to ``selector`` first: :func:`load_views`). Stops when the targets are reached,
    ``max_views`` are kept, ``stop_requested()`` gives a reason (the operator pressed Enter) or ``max_seconds``
    pass. Errors from ``grab`` (a stalled or lost camera) propagate; the views kept so far are on disk already.
    """
    save.mkdir(parents=True, exist_ok=True)
    t0 = clock()
    last_index = -1
    seen = 0
    paths = sorted(save.glob(VIEW_GLOB))
    last = "waiting for the first frame"
    shown_at = -math.inf
    while True:
        elapsed = clock() - t0
        if not selector.missing():
            stop = "targets reached"
            break
        if len(selector.views) >= selector.targets.max_views:
            stop = f"{selector.targets.max_views} views kept (the maximum)"
            break
        requested = stop_requested()
        if requested:
            stop = requested
            break
        if elapsed > selector.targets.max_seconds:
            stop = f"time limit ({selector.targets.max_seconds:.0f} s)"
            break
        image, index = grab()
        if index == last_index:
            time.sleep(0.01)
            continue
        last_index = index
        seen += 1
        gray: Image = np.asarray(cv2.cvtColor(image, cv2.COLOR_RGB2GRAY) if image.ndim == 3 else image, np.uint8)
        n = len(paths)
        det = detector.detect(gray, name=f"{n:03d}.png")
        offer = selector.offer(det)
        last = ("kept: " if offer.kept else "skipped: ") + offer.reason
        if offer.kept:
            path = save / f"{n:03d}.png"
            cv2.imwrite(str(path), gray)
            paths.append(path)
        now = clock()
        if offer.kept or now - shown_at >= 1.0:  # the display and the preview refresh at most once a second
            shown_at = now
            if show is not None:
                show(status_lines(selector, now - t0, last))
            if preview is not None:
                write_preview(preview, image, selector, det)
    if show is not None:
        show(status_lines(selector, clock() - t0, last))
    return LiveResult(views=tuple(paths), stop=stop, seconds=clock() - t0, frames_seen=seen)
