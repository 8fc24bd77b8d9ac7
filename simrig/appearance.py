"""The simulated rig's look: ``flat`` (flat colours, one fixed light, clean images) or ``varied``.

``flat`` is the cartoon look the rig always had: saturated flat colours on a grey scene, a fixed key
light, no texture, no camera noise. ``varied`` is there so perception shortcuts tuned to flat colours
do not survive:

* **textures** (compiled into the scene once): the table gets one of :data:`TABLE_MATERIALS` procedural
  wood or speckle materials (low saturation, so the table never passes a colour-blob detector's
  saturation test), switched per episode through ``model.geom_matid``; every task object or fixture
  geom that only has a flat colour gets a subtle noise texture of its own colour (mean kept within a
  few percent of the flat colour; hue unchanged), objects with their own texture keep it;
* **lighting** drawn per episode: the key light's position, direction, intensity, colour and ambient
  term, the headlight's strength, and shadow maps on (set on the compiled model, no recompile);
* **camera effects** on every rendered image (:func:`camera_effects`): exposure gain, white balance
  (per-channel gains that partly undo the light's tint, as auto white balance does), sensor noise
  (Gaussian read noise plus shot noise whose variance grows with the signal), and JPEG compression.

Everything is seeded: the per-episode :class:`Look` is drawn from ``(seed, subtask)``
(:func:`draw_look`), and a frame's noise from ``(seed, subtask, frame, camera)``, so two robots reset
alike produce byte-identical observations (a paired run's two branches start from the same image).
Physics never reads any of it.
"""

from __future__ import annotations

import functools
import math
import zlib
from collections.abc import Sequence
from dataclasses import dataclass, replace
from statistics import NormalDist
from typing import Any

import cv2
import numpy as np
from numpy.typing import NDArray

from simrig.objects import Assets, FixtureSpec, GeomSpec, ObjectSpec
from simrig.tasks.textures import png_bytes

APPEARANCES = ("flat", "varied")
DEFAULT_APPEARANCE = "flat"

Vec3 = tuple[float, float, float]

# Table materials of the varied look: (pattern, light colour, dark colour); saturation ≤ 0.2 everywhere,
# far below the 0.35 a colour-blob detector needs (pilworld.perception.colour), so the table stays "grey".
TABLE_MATERIALS: tuple[tuple[str, Vec3, Vec3], ...] = (
    ("wood", (0.76, 0.71, 0.63), (0.60, 0.55, 0.48)),
    ("wood", (0.66, 0.62, 0.57), (0.50, 0.46, 0.42)),
    ("speckle", (0.74, 0.74, 0.72), (0.58, 0.58, 0.57)),
    ("speckle", (0.70, 0.72, 0.75), (0.55, 0.57, 0.60)),
)
TABLE_TEXTURE_PX = 256
TABLE_PERIOD_M = 0.5  # one period of a table texture spans this many metres
OBJECT_TEXTURE_PX = 64
OBJECT_CONTRAST = 0.09  # standard deviation of the brightness factor of an object's noise texture
# Render quality of the varied look. Mesa renders on the CPU, where a shadow-casting light costs three
# more passes over the scene (depth map, ambient, lit): a 512² map with MuJoCo's default 28-slice
# primitives and 4× multisampling made a 128² view ~5× slower, too slow for the ≥ 5× real-time budget.
# A 256² map (≈ 1.3 cm per texel on the table), 12-slice primitives and no multisampling (the camera
# model's blur anti-aliases instead) cost 2–2.4× a flat view; docs/sim_rig.md has the measurements.
SHADOW_SIZE = 256
NUM_SLICES = 12
NUM_STACKS = 8
OFF_SAMPLES = 0
KEY_LIGHT = "key"
TABLE_GEOM = "table"
TABLE_CENTRE = (-0.05, 0.0, 0.0)


def check_appearance(name: object) -> str:
    """``name`` if it is one of :data:`APPEARANCES`, else ``ValueError``."""
    if not isinstance(name, str) or name not in APPEARANCES:
        raise ValueError(f"appearance: expected one of {', '.join(APPEARANCES)}, got {name!r}")
    return name


@dataclass(frozen=True)
class Look:
    """One episode's draw of the varied look (see :func:`draw_look`); ``seed``/``subtask`` key the frame noise."""

    seed: int
    subtask: int
    table_material: int  # index into TABLE_MATERIALS
    light_pos: Vec3  # key light, world frame [m]
    light_dir: Vec3  # unit vector
    light_diffuse: Vec3
    light_ambient: Vec3
    light_specular: Vec3
    headlight_ambient: float
    headlight_diffuse: float
    exposure: float  # gain on every pixel
    white_balance: Vec3  # per-channel gains (green = 1)
    blur: float  # Gaussian optical blur, standard deviation [px] (also the anti-aliasing)
    read_noise: float  # Gaussian noise standard deviation [DN]
    shot_noise: float  # shot-noise variance per DN of signal [DN]
    jpeg_quality: int


def draw_look(seed: int, subtask: int = 0) -> Look:
    """The varied look of episode ``(seed, subtask)``: the same pair always gives the same look."""
    for name, value in (("seed", seed), ("subtask", subtask)):
        if isinstance(value, bool) or not isinstance(value, int) or value < 0:
            raise ValueError(f"{name}: expected an integer >= 0, got {value!r}")
    rng = np.random.default_rng([seed, subtask, 0xA99E])  # a stream of its own (layouts use other keys)
    table = int(rng.integers(len(TABLE_MATERIALS)))
    # Key light: a spot 1.6–2.0 m from a point near the table centre, 10–40° off vertical, any azimuth.
    target = np.asarray(TABLE_CENTRE) + np.r_[rng.uniform(-0.15, 0.15, 2), 0.0]
    azimuth, tilt = rng.uniform(0.0, 2 * math.pi), math.radians(rng.uniform(10.0, 40.0))
    dist = rng.uniform(1.6, 2.0)
    offset = dist * np.array([math.sin(tilt) * math.cos(azimuth), math.sin(tilt) * math.sin(azimuth), math.cos(tilt)])
    pos = target + offset
    direction = -offset / dist
    # Colour temperature: warm (t = −1) to cool (t = +1), mean channel gain 1.
    t = rng.uniform(-1.0, 1.0)
    tint = np.array([1.0 - 0.08 * t, 1.0, 1.0 + 0.10 * t])
    tint /= tint.mean()
    intensity = rng.uniform(0.30, 0.55)
    ambient = rng.uniform(0.0, 0.08)
    specular = rng.uniform(0.05, 0.20)
    # Auto white balance undoes most of the tint, with a residual error of a few percent per channel.
    wb = tint ** (-0.8) * rng.uniform(0.96, 1.04, 3)
    wb /= wb[1]
    return Look(
        seed=seed,
        subtask=subtask,
        table_material=table,
        light_pos=_vec3(pos),
        light_dir=_vec3(direction),
        light_diffuse=_vec3(intensity * tint),
        light_ambient=_vec3(ambient * tint),
        light_specular=(specular, specular, specular),
        headlight_ambient=float(rng.uniform(0.20, 0.32)),
        headlight_diffuse=float(rng.uniform(0.15, 0.30)),
        exposure=float(math.exp(rng.uniform(math.log(0.85), math.log(1.1)))),
        white_balance=_vec3(wb),
        blur=float(rng.uniform(0.45, 0.75)),
        read_noise=float(rng.uniform(1.5, 4.5)),
        shot_noise=float(rng.uniform(0.01, 0.06)),
        jpeg_quality=int(rng.integers(70, 91)),
    )


def _vec3(v: Any) -> Vec3:
    a = np.asarray(v, dtype=np.float64)
    return (float(a[0]), float(a[1]), float(a[2]))


def _normal_quantiles() -> NDArray[np.float32]:
    q = np.array([NormalDist().inv_cdf((k + 0.5) / 256) for k in range(256)])
    return np.asarray(q / q.std(), dtype=np.float32)


# The normal distribution's quantiles at (k + 0.5) / 256, k = 0..255, rescaled to unit variance.
_NORMAL_QUANTILES = _normal_quantiles()


def frame_rng(look: Look, frame: int, camera: str) -> np.random.Generator:
    """The noise generator of one frame: a function of (seed, subtask, frame, camera) only."""
    if isinstance(frame, bool) or not isinstance(frame, int) or frame < 0:
        raise ValueError(f"frame: expected an integer >= 0, got {frame!r}")
    return np.random.default_rng([look.seed, look.subtask, frame, zlib.crc32(camera.encode()), 0xCA3])


def camera_effects(image: NDArray[np.uint8], look: Look, *, frame: int, camera: str) -> NDArray[np.uint8]:
    """``image`` (uint8 RGB ``(H, W, 3)``) as a camera would deliver it under ``look``: a new array.

    Exposure and white-balance gains, then sensor noise (variance ``read² + shot·signal`` in DN), then
    rounding and a JPEG round trip at ``look.jpeg_quality``. The noise is drawn from
    :func:`frame_rng`, so the same ``(look, frame, camera)`` and image always give the same bytes.
    """
    img = np.asarray(image)
    if img.dtype != np.uint8 or img.ndim != 3 or img.shape[2] != 3:
        raise ValueError(f"image: expected uint8 (H, W, 3), got {img.dtype} {img.shape}")
    rng = frame_rng(look, frame, camera)
    gains = np.asarray(look.white_balance, dtype=np.float32) * np.float32(look.exposure)
    x = np.multiply(img, gains, dtype=np.float32)
    if look.blur > 0:
        x = cv2.GaussianBlur(x, (0, 0), look.blur, borderType=cv2.BORDER_REFLECT)
    sigma = np.sqrt(np.float32(look.read_noise) ** 2 + np.float32(look.shot_noise) * x)
    # Unit normal noise from random bytes through a 256-entry quantile table: ~10× faster than
    # standard_normal at this size, and as deterministic. In-place arithmetic and cv2's channel swaps
    # (rather than numpy's reversed views) give the same bytes for ~25 % less time per frame.
    z = _NORMAL_QUANTILES[np.frombuffer(rng.bytes(x.size), dtype=np.uint8).reshape(x.shape)]
    z *= sigma
    x += z
    x += np.float32(0.5)
    np.clip(x, 0.0, 255.0, out=x)
    bgr = cv2.cvtColor(x.astype(np.uint8), cv2.COLOR_RGB2BGR)
    ok, buf = cv2.imencode(".jpg", bgr, [cv2.IMWRITE_JPEG_QUALITY, look.jpeg_quality])
    if not ok:
        raise ValueError("camera_effects: JPEG encoding failed")
    decoded = cv2.imdecode(buf, cv2.IMREAD_COLOR)
    if decoded is None:
        raise ValueError("camera_effects: JPEG decoding failed")
    return np.asarray(cv2.cvtColor(decoded, cv2.COLOR_BGR2RGB), dtype=np.uint8)


def apply_look(model: Any, look: Look) -> None:
    """Set ``look``'s lighting and table material on a compiled varied scene (``mj_forward`` follows)."""
    key = model.light(KEY_LIGHT).id
    model.light_pos[key] = look.light_pos
    model.light_dir[key] = look.light_dir
    model.light_diffuse[key] = look.light_diffuse
    model.light_ambient[key] = look.light_ambient
    model.light_specular[key] = look.light_specular
    model.light_castshadow[key] = 1
    model.vis.headlight.ambient[:] = look.headlight_ambient
    model.vis.headlight.diffuse[:] = look.headlight_diffuse
    model.geom_matid[model.geom(TABLE_GEOM).id] = model.material(table_material_name(look.table_material)).id


# ---------------------------------------------------------------------------------------------- textures


def _periodic_noise(rng: np.random.Generator, n: int, cells: int) -> NDArray[np.float64]:
    """Smooth noise on an ``n``×``n`` tile that wraps around (so a repeated texture shows no seams)."""
    coarse = rng.standard_normal((cells, cells))
    big = cv2.resize(np.tile(coarse, (3, 3)), (3 * n, 3 * n), interpolation=cv2.INTER_CUBIC)
    return np.asarray(big[n : 2 * n, n : 2 * n], dtype=np.float64)


def _fbm(rng: np.random.Generator, n: int, cells: Sequence[int]) -> NDArray[np.float64]:
    """Several octaves of periodic noise, normalised to mean 0 and standard deviation 1."""
    t = np.zeros((n, n))
    for k, c in enumerate(cells):
        t += _periodic_noise(rng, n, c) / (k + 1)
    return np.asarray((t - t.mean()) / max(float(t.std()), 1e-9), dtype=np.float64)


def table_material_name(index: int) -> str:
    return f"appearance_table{index}"


@functools.lru_cache(maxsize=len(TABLE_MATERIALS))
def table_image(index: int) -> NDArray[np.uint8]:
    """The texture of table material ``index``: wood grain or a speckled laminate (RGB uint8)."""
    pattern, light, dark = TABLE_MATERIALS[index]
    n = TABLE_TEXTURE_PX
    rng = np.random.default_rng([index, 0x7AB1E])
    v, u = np.mgrid[0:n, 0:n] / n
    if pattern == "wood":
        warp = 0.12 * _fbm(rng, n, (2, 4)) + 0.05 * np.sin(2 * math.pi * v)
        grain = 0.5 + 0.5 * np.sin(2 * math.pi * (10 * u + 2 * warp))  # rings along u, wobbling along v
        fibres = _fbm(rng, n, (128,)) * 0.6 + 0.4 * _fbm(rng, n, (16,))
        t = np.clip(0.15 + 0.7 * grain**2 + 0.12 * fibres, 0.0, 1.0)
    else:
        blotch = _fbm(rng, n, (4, 8, 16))
        fleck = rng.random((n, n))
        t = np.clip(0.5 + 0.2 * blotch + 0.5 * (fleck > 0.97) - 0.4 * (fleck < 0.03), 0.0, 1.0)
    img = np.asarray(dark)[None, None, :] * (1 - t[..., None]) + np.asarray(light)[None, None, :] * t[..., None]
    return np.asarray(np.clip(img * 255.0 + 0.5, 0, 255), dtype=np.uint8)


@functools.lru_cache(maxsize=256)
def object_image(rgb: Vec3) -> NDArray[np.uint8]:
    """A subtle noise texture of colour ``rgb`` (RGB uint8): brightness noise around it, same hue.

    Each pixel is ``rgb`` times a brightness factor (a few octaves of smooth noise and a fine grain,
    standard deviation ≈ :data:`OBJECT_CONTRAST`); the factor is rescaled so the texture's mean stays
    within ~1 % of the flat colour even where bright channels clip.
    """
    n = OBJECT_TEXTURE_PX
    colour = np.clip(np.asarray(rgb, dtype=np.float64), 0.0, 1.0)
    key = [round(float(c) * 1000) for c in colour]
    rng = np.random.default_rng([*key, 0x0B7EC7])
    factor = 1.0 + OBJECT_CONTRAST * (0.85 * _fbm(rng, n, (4, 8)) + 0.5 * rng.standard_normal((n, n)))
    img = colour[None, None, :] * factor[..., None]
    for _ in range(3):  # clipping at 1 darkens a bright colour's mean: scale back up where there is room
        mean = np.clip(img, 0.0, 1.0).reshape(-1, 3).mean(axis=0)
        img = img * np.where(mean > 1e-6, colour / np.maximum(mean, 1e-6), 1.0)[None, None, :]
    return np.asarray(np.clip(img * 255.0 + 0.5, 0, 255), dtype=np.uint8)


def table_assets() -> Assets:
    """The varied look's table textures and materials (2d textures, one period ``TABLE_PERIOD_M`` long)."""
    xml: list[str] = []
    files: list[tuple[str, bytes]] = []
    for k in range(len(TABLE_MATERIALS)):
        name = table_material_name(k)
        fname = f"{name}.png"
        repeat = 1.0 / TABLE_PERIOD_M
        xml.append(f'<texture name="{name}_tex" type="2d" file="{fname}"/>')
        xml.append(
            f'<material name="{name}" texture="{name}_tex" texrepeat="{repeat:.6g} {repeat:.6g}" texuniform="true" '
            'specular="0.1" shininess="0.3"/>'
        )
        files.append((fname, png_bytes(table_image(k))))
    return Assets(tuple(xml), tuple(files))


def _colour_key(rgb: Vec3) -> str:
    return "".join(f"{round(min(max(c, 0.0), 1.0) * 1000):04d}" for c in rgb)


def _colour_material(rgb: Vec3) -> tuple[str, Assets]:
    name = f"appearance_c{_colour_key(rgb)}"
    fname = f"{name}.png"
    # MuJoCo wraps a cube texture once across each face (texrepeat does not apply): a few blobs per face.
    xml = (
        f'<texture name="{name}_tex" type="cube" file="{fname}"/>',
        f'<material name="{name}" texture="{name}_tex"/>',
    )
    return name, Assets(xml, ((fname, png_bytes(object_image(rgb))),))


def textured_scene(
    objects: Sequence[ObjectSpec], fixtures: Sequence[FixtureSpec]
) -> tuple[tuple[ObjectSpec, ...], tuple[FixtureSpec, ...], Assets]:
    """The varied look's objects and fixtures: every untextured geom gets a noise texture of its colour.

    Returns the new specs and the assets they need in addition to their own (one texture per distinct
    colour, then the table materials). Geoms with a material keep it.
    """
    materials: dict[str, str] = {}  # by colour key (a thousandth per channel)
    assets = Assets()

    def retexture(g: GeomSpec) -> GeomSpec:
        nonlocal assets
        if g.material is not None:
            return g
        rgb = (g.rgba[0], g.rgba[1], g.rgba[2])
        key = _colour_key(rgb)
        if key not in materials:
            materials[key], extra = _colour_material(rgb)
            assets = assets + extra
        return replace(g, material=materials[key], rgba=(1.0, 1.0, 1.0, g.rgba[3]))

    new_objects = tuple(replace(o, geoms=tuple(retexture(g) for g in o.geoms)) for o in objects)
    new_fixtures = tuple(replace(f, geoms=tuple(retexture(g) for g in f.geoms)) for f in fixtures)
    return new_objects, new_fixtures, assets + table_assets()
