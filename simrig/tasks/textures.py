"""Textures of a task file: an image file or a procedural pattern, as MuJoCo texture and material assets.

Objects get ``cube`` textures (MuJoCo maps them onto every primitive, cylinders and spheres included; a
``2d`` texture only maps well onto flat faces). MuJoCo ignores ``texrepeat`` for cube textures and wraps
the image once across each face of the geom, so the image is tiled here instead: ``round(extent / scale)``
periods across the object's largest extent keep one period about ``scale`` metres long whatever the
object's size. Fixtures (flat, ``2d``) use ``texuniform`` with ``texrepeat = 1/scale``, which MuJoCo
honours for 2-D textures. Procedural patterns are drawn here with numpy and encoded as PNG, so a task
file needs no image to be textured.
"""

from __future__ import annotations

import functools

import cv2
import numpy as np
from numpy.typing import NDArray

from simrig.objects import Assets
from simrig.tasks.schema import Texture

RGB = tuple[float, float, float]
SIZE = 64  # pixels per pattern period


def _shade(rgb: RGB, factor: float) -> RGB:
    if factor >= 1.0:
        return (
            rgb[0] + (1 - rgb[0]) * (factor - 1),
            rgb[1] + (1 - rgb[1]) * (factor - 1),
            rgb[2] + (1 - rgb[2]) * (factor - 1),
        )
    return (rgb[0] * factor, rgb[1] * factor, rgb[2] * factor)


def pattern_image(pattern: str, a: RGB, b: RGB, seed: int = 0) -> NDArray[np.uint8]:
    """One period of ``pattern`` in colours ``a`` and ``b``: ``(SIZE, SIZE, 3)`` RGB uint8."""
    n = SIZE
    v, u = np.mgrid[0:n, 0:n] / n
    if pattern == "checker":
        t = ((u < 0.5) ^ (v < 0.5)).astype(np.float64)
    elif pattern == "stripes":
        t = (u < 0.5).astype(np.float64)
    elif pattern == "dots":
        t = (np.hypot(u - 0.5, v - 0.5) < 0.3).astype(np.float64)
    elif pattern == "noise":
        rng = np.random.default_rng(seed)
        coarse = rng.random((8, 8))
        t = cv2.resize(np.tile(coarse, (2, 2)), (2 * n, 2 * n), interpolation=cv2.INTER_CUBIC)[
            n // 2 : n // 2 + n, n // 2 : n // 2 + n
        ]
        t = np.clip((t - t.min()) / max(float(np.ptp(t)), 1e-9), 0.0, 1.0)
    elif pattern == "wood":
        rng = np.random.default_rng(seed)
        wobble = 0.04 * np.sin(2 * np.pi * (v * 2 + rng.random()))
        t = 0.5 + 0.5 * np.sin(2 * np.pi * (4 * u + wobble))
    else:
        raise ValueError(f"unknown texture pattern {pattern!r} (checker, stripes, dots, noise, wood)")
    img = np.asarray(a)[None, None, :] * (1 - t[..., None]) + np.asarray(b)[None, None, :] * t[..., None]
    return np.asarray(np.clip(img * 255.0 + 0.5, 0, 255), dtype=np.uint8)


@functools.lru_cache(maxsize=64)
def _read_image(path: str) -> NDArray[np.uint8]:
    bgr = cv2.imread(path, cv2.IMREAD_COLOR)
    if bgr is None:
        raise ValueError(f"texture image {path} cannot be read as an image")
    if max(bgr.shape[:2]) > 1024:
        raise ValueError(f"texture image {path} is {bgr.shape[1]}x{bgr.shape[0]} (at most 1024 on a side)")
    return np.asarray(bgr[:, :, ::-1], dtype=np.uint8)


def texture_image(texture: Texture, colour: RGB | None, seed: int = 0) -> NDArray[np.uint8]:
    """The RGB image a texture stands for (a file's pixels, or one period of a pattern)."""
    if texture.image is not None:
        return _read_image(texture.image)
    base = colour if colour is not None else (0.6, 0.6, 0.6)
    a, b = texture.colours if texture.colours is not None else (_shade(base, 1.25), _shade(base, 0.7))
    assert texture.pattern is not None
    return pattern_image(texture.pattern, a, b, seed)


def png_bytes(image: NDArray[np.uint8]) -> bytes:
    ok, buf = cv2.imencode(".png", np.ascontiguousarray(image[:, :, ::-1]))
    if not ok:
        raise ValueError("could not encode a texture as PNG")
    return bytes(buf.tobytes())


MAX_TILES = 16  # periods across one face of an object's cube texture
MAX_TILED = 512  # pixels on a side of a tiled cube texture


def tiles(extent: float, scale: float) -> int:
    """Pattern periods across an object ``extent`` metres wide for a period of ``scale`` metres (1…16)."""
    return max(1, min(MAX_TILES, round(extent / scale)))


def tiled(image: NDArray[np.uint8], n: int) -> NDArray[np.uint8]:
    """``image`` repeated ``n`` × ``n`` times, shrunk to at most :data:`MAX_TILED` pixels on a side."""
    if n <= 1:
        return image
    out = np.asarray(np.tile(image, (n, n, 1)), dtype=np.uint8)
    if max(out.shape[:2]) > MAX_TILED:
        f = MAX_TILED / max(out.shape[:2])
        size = (max(1, round(out.shape[1] * f)), max(1, round(out.shape[0] * f)))
        out = np.asarray(cv2.resize(out, size, interpolation=cv2.INTER_AREA), dtype=np.uint8)
    return out


def mean_colour(texture: Texture, colour: RGB | None, name: str) -> RGB:
    """The mean colour of ``name``'s texture (what finds the object in an image)."""
    mean = texture_image(texture, colour, seed=sum(name.encode())).reshape(-1, 3).mean(axis=0) / 255.0
    return (float(mean[0]), float(mean[1]), float(mean[2]))


def texture_assets(
    name: str, texture: Texture, colour: RGB | None, kind: str = "cube", extent: float | None = None
) -> tuple[Assets, str, RGB]:
    """(assets, material name, mean colour) for ``name``'s texture; ``extent``: an object's largest size [m]."""
    image = texture_image(texture, colour, seed=sum(name.encode()))
    mean = mean_colour(texture, colour, name)
    tex, mat, fname = f"tex_{name}", f"mat_{name}", f"tex_{name}.png"
    if kind == "cube":  # wrapped once per face: tile the image itself
        image = tiled(image, tiles(extent if extent is not None else texture.scale, texture.scale))
        material = f'<material name="{mat}" texture="{tex}" texuniform="true"/>'
    else:
        repeat = 1.0 / texture.scale
        material = f'<material name="{mat}" texture="{tex}" texrepeat="{repeat:.6g} {repeat:.6g}" texuniform="true"/>'
    xml = (f'<texture name="{tex}" type="{kind}" file="{fname}"/>', material)
    return Assets(xml, ((fname, png_bytes(image)),)), mat, mean
