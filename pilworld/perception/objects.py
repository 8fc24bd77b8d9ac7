"""Which coloured objects a scene holds, learnt from one frame of it: no object list, no task file.

The hand-written judges looked objects up by name (each task's colours written in code). What a camera
shows is enough to find them when objects are coloured and the rest of the scene is not (the arms and
grippers are grey, the table low in saturation): every saturated hue that forms a compact blob is an
object's colour. :func:`discover_colours` finds those hues in an image; the result feeds
:func:`pilworld.perception.colour.segment` like a hand-written palette would.

How: the hue histogram of the saturated pixels (outside ``exclude``, e.g. the predicted arms), its
peaks at least :data:`MIN_SEPARATION_DEG` apart, and for each peak the pixels within half that distance
of it: kept when their largest 8-connected blob has at least ``min_pixels`` pixels and holds at least
:data:`MIN_COMPACT` of them. The second test is what rejects a textured table whose grains pass the
saturation test (sand, wood): its pixels of any hue are scattered in many small specks. Limits: two
objects of one colour are one class (their largest blob is the one tracked); an object whose colour is
as grey as the table is not found; objects closer in hue than :data:`MIN_SEPARATION_DEG` merge.
"""

from __future__ import annotations

import colorsys

import cv2
import numpy as np
from numpy.typing import NDArray

from pilworld.perception.colour import ColourClass

MIN_SATURATION = 0.35  # as colour.segment's default: below it a hue is not an object's
MIN_VALUE = 0.12
MIN_SEPARATION_DEG = 14.0  # hue peaks closer than this are one colour (the rig's palettes are ≥ 17° apart)
MIN_COMPACT = 0.5  # the largest blob holds at least this share of a colour's pixels (else: texture)
MIN_PIXELS = 6  # at 128 px width; scaled with the image's area


def discover_colours(
    image: NDArray[np.uint8], exclude: NDArray[np.bool_] | None = None, min_pixels: int | None = None
) -> list[ColourClass]:
    """The object colours of ``image`` (uint8 RGB ``(H, W, 3)``), most pixels first; [] when none.

    ``exclude`` (``(H, W)`` bool) masks pixels that are known not to be objects (the arms);
    ``min_pixels`` defaults to :data:`MIN_PIXELS` scaled from a 128 × 128 image.
    """
    return [_colour(p) for p in _object_hues(image, exclude, min_pixels)]


def discover_colours_over(
    frames: NDArray[np.uint8], exclude: NDArray[np.bool_] | None = None, samples: int = 8
) -> list[ColourClass]:
    """:func:`discover_colours` over up to ``samples`` frames spread over ``frames`` ``(T, H, W, 3)``, united.

    One frame misses what an arm hides in it (at a subtask's start the arm often stands over the
    objects); a colour found in any sampled frame is kept, once (hues closer than
    :data:`MIN_SEPARATION_DEG` are one colour; the first frame's hue, else the earliest, names it).
    ``exclude``: ``(T, H, W)`` masks of non-object pixels per frame.
    """
    if frames.ndim != 4 or len(frames) == 0:
        raise ValueError(f"frames: expected (T, H, W, 3) with T >= 1, got {frames.shape}")
    T = len(frames)
    picks = sorted({int(t) for t in np.linspace(0, T - 1, min(max(samples, 1), T)).round()})
    steps: list[int] = []
    for t in picks:
        for p in _object_hues(frames[t], None if exclude is None else exclude[t], None):
            if _distinct(p, steps):
                steps.append(p)
    return [_colour(p) for p in steps]


def _object_hues(image: NDArray[np.uint8], exclude: NDArray[np.bool_] | None, min_pixels: int | None) -> list[int]:
    """:func:`discover_colours`' hues as OpenCV hue steps (0..179, 2° each), most pixels first."""
    img = np.asarray(image)
    if img.ndim != 3 or img.shape[2] != 3 or img.dtype != np.uint8:
        raise ValueError(f"image: expected uint8 (H, W, 3), got {img.dtype} {img.shape}")
    h, w = img.shape[:2]
    if exclude is not None and exclude.shape != (h, w):
        raise ValueError(f"exclude: expected a ({h}, {w}) mask, got {exclude.shape}")
    least = min_pixels if min_pixels is not None else max(3, round(MIN_PIXELS * h * w / 128**2))
    hsv = cv2.cvtColor(img, cv2.COLOR_RGB2HSV)
    sat = (hsv[..., 1] >= np.ceil(MIN_SATURATION * 255)) & (hsv[..., 2] >= np.ceil(MIN_VALUE * 255))
    if exclude is not None:
        sat &= ~exclude
    hue = hsv[..., 0].astype(np.int64)  # OpenCV: 0..179, 2° per step
    counts = np.bincount(hue[sat], minlength=180)[:180].astype(np.float64)
    kernel = np.array([1.0, 2.0, 3.0, 2.0, 1.0]) / 9.0
    smooth = np.convolve(np.concatenate([counts[-2:], counts, counts[:2]]), kernel, mode="valid")
    peaks = [
        i for i in range(180) if smooth[i] > 0 and smooth[i] >= smooth[i - 1] and smooth[i] > smooth[(i + 1) % 180]
    ]
    kept: list[int] = []
    for p in sorted(peaks, key=lambda i: -smooth[i]):
        if _distinct(p, kept):
            kept.append(p)
    half = MIN_SEPARATION_DEG / 4.0  # a colour's pixels: within half the separation of its peak (hue steps)
    found: list[tuple[int, int]] = []  # (pixels in the largest blob, hue step)
    for p in kept:
        near = sat & (np.minimum(np.abs(hue - p), 180 - np.abs(hue - p)) <= half)
        total = int(near.sum())
        if total < least:
            continue
        n, _, stats, _ = cv2.connectedComponentsWithStats(near.astype(np.uint8), connectivity=8)
        largest = int(stats[1:, cv2.CC_STAT_AREA].max()) if n > 1 else 0
        if largest >= least and largest >= MIN_COMPACT * total:
            found.append((largest, p))
    found.sort(reverse=True)
    return [p for _, p in found]


def _distinct(step: int, kept: list[int]) -> bool:
    """Whether hue ``step`` is at least :data:`MIN_SEPARATION_DEG` from every hue in ``kept`` (OpenCV steps)."""
    return all(_hue_steps(step, q) >= MIN_SEPARATION_DEG / 2.0 for q in kept)


def _hue_steps(a: int, b: int) -> float:
    d = abs(a - b)
    return float(min(d, 180 - d))


def _colour(step: int) -> ColourClass:
    r, g, b = colorsys.hsv_to_rgb((2.0 * step % 360.0) / 360.0, 1.0, 1.0)
    return ColourClass(name=f"hue_{2 * step:03d}", rgb=(r, g, b))
