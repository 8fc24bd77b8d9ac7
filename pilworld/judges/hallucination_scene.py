"""What the hallucination detector sees in an episode: arm silhouettes from FK, arm pixels, object pixels.

Why a silhouette: the state of every frame (the measured joints in the real branch, the commanded
stride-aligned action in the imagined one) says where each arm *must* appear in the head view. The
arms are drawn as capsules along the DH offsets of the UR chain (the links), spheres at the joints
(the housings) and a capsule from the flange through the palm to the fingertips (the gripper), each
projected through the rig's head ``CameraModel`` with its radius scaled by depth. It is coarse (no
shading, no exact housings), so every comparison with the image allows a pixel or two of slack, but
it tells "the arm is there" from "the arm is not there" on every frame of every episode
(measured recall of the drawn forearm-to-gripper silhouette on observed arm pixels: ≥ 0.77, median
0.96, over 9,120 arm-frames of the simulated training set).

Why the empty scene for "arm pixels": a pixel is *table* when it is what the episode's empty scene
shows there (:class:`Background`: learnt pixel by pixel from the start frame and the first frames where
no arm is drawn near a pixel and no object is on it, so textures, shading and a tinted light are
explained where one table colour is not — the varied look's wood and laminate tables), *shadow* when it
is that scene darker or lighter by the episode's own shadow tint (:func:`shadow_tint`), *object* when
:func:`pilworld.perception.colour.segment` gives it a class, and *arm-like* otherwise. Where no frame
shows a pixel empty, one table colour learnt from the start frame decides (``learn_table``; the flat
look's beige table under a white light), and under an arm that never moves nothing does. Where arm and
table are the same grey the image cannot tell them apart; ``arm_visibility`` (hallucination_checks.py)
measures how well it can, per episode, and the checks lean on the drawn arm where it cannot. Static
dark fixtures (slot outlines, the stacking mark, the table edge) are part of the empty scene.

Pixel lengths and areas below are tuned at 128×128 and scale with the image width.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import cv2
import numpy as np
from numpy.typing import NDArray

from calib.camera_model import CameraModel
from pilworld.config.rig import RigConfig
from pilworld.kinematics.dual_arm import ArmMount
from pilworld.kinematics.fk import fk_frames
from pilworld.perception.colour import ColourClass, segment
from pilworld.types import LEFT_ARM, RIGHT_ARM

Mask = NDArray[np.bool_]
Image = NDArray[np.uint8]
REFERENCE_WIDTH = 128  # the image width the pixel thresholds are tuned at


@dataclass(frozen=True)
class ArmShape:
    """A coarse visual model of a UR arm with a parallel-jaw gripper (metres), for silhouettes only."""

    link_radius: tuple[float, ...] = (0.045, 0.045, 0.045, 0.034, 0.034, 0.034)  # capsule along DH offset i
    joint_radius: tuple[float, ...] = (0.048, 0.048, 0.048, 0.036, 0.036, 0.036)  # housing at joint i
    coupling_radius: float = 0.035  # flange → palm cylinder
    palm_half_width: float = 0.05  # palm box half-size along the closing (tool y) axis
    palm_radius: float = 0.025
    palm_below_tcp: float = 0.06  # palm centre above the TCP, along the tool axis
    finger_radius: float = 0.02
    distal_from_link: int = 2  # links from this index on (the forearm) count as "distal"

    def capsules(self, mount: ArmMount, q6: NDArray[np.float64]) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """``(T, 6)`` joints → capsule end points ``(T, N, 2, 3)`` in the rig frame and radii ``(N,)``.

        Capsules are ordered base → gripper; the last three are the gripper (coupling, palm, fingers).
        """
        frames = mount.T_rig_base @ fk_frames(q6, mount.dh)  # (T, 7, 4, 4)
        origin = frames[..., :3, 3]
        ends: list[NDArray[np.float64]] = []
        radii: list[float] = []
        for i in range(6):
            ends.append(np.stack([origin[:, i], origin[:, i + 1]], axis=1))
            radii.append(self.link_radius[i])
            z = frames[:, i, :3, 2]  # the joint axis: the housing is a short cylinder along it
            r = self.joint_radius[i]
            ends.append(np.stack([origin[:, i] - z * r * 0.8, origin[:, i] + z * r * 0.8], axis=1))
            radii.append(r)
        tcp = frames[:, 6] @ mount.T_flange_tcp
        p, y, z = tcp[:, :3, 3], tcp[:, :3, 1], tcp[:, :3, 2]
        palm = p - self.palm_below_tcp * z
        ends.append(np.stack([origin[:, 6], palm], axis=1))
        radii.append(self.coupling_radius)
        ends.append(np.stack([palm - self.palm_half_width * y, palm + self.palm_half_width * y], axis=1))
        radii.append(self.palm_radius)
        ends.append(np.stack([p - 0.03 * z, p + 0.01 * z], axis=1))
        radii.append(self.finger_radius)
        return np.stack(ends, axis=1), np.asarray(radii)

    def first_distal(self) -> int:
        """Index of the first distal capsule in :meth:`capsules` (two per link: offset, housing)."""
        return 2 * self.distal_from_link


@dataclass(frozen=True, eq=False)
class ArmViews:
    """Predicted arms in the head view, per frame: silhouettes and projected TCPs."""

    whole: NDArray[np.uint8]  # (T, H, W) 1 where either arm is predicted
    distal: NDArray[np.uint8]  # (2, T, H, W) forearm → fingertips of the left / right arm
    gripper: NDArray[np.uint8]  # (2, T, H, W) the gripper and last wrist of the left / right arm
    tcp_uv: NDArray[np.float64]  # (2, T, 2) projected TCPs
    tcp_visible: NDArray[np.bool_]  # (2, T)


def predict_arms(rig: RigConfig, state: NDArray[np.floating], shape: ArmShape | None = None) -> ArmViews:
    """Draw both arms of ``state`` ``(T, 14)`` into the head view of ``rig``."""
    shape = shape or ArmShape()
    cam = rig.head_camera_model
    kin = rig.kinematics
    q = np.asarray(state, dtype=np.float64)
    T = q.shape[0]
    whole = np.zeros((T, cam.height, cam.width), np.uint8)
    distal = np.zeros((2, T, cam.height, cam.width), np.uint8)
    gripper = np.zeros_like(distal)
    tcp_uv = np.zeros((2, T, 2))
    tcp_visible = np.zeros((2, T), bool)
    first_distal = shape.first_distal()
    for a, (mount, joints) in enumerate(((kin.left, LEFT_ARM), (kin.right, RIGHT_ARM))):
        ends, radii = shape.capsules(mount, q[:, joints])
        proj = cam.project_detailed(ends)  # uv (T, N, 2, 2), depth (T, N, 2)
        tcp = kin.gripper_points(q)[:, a]
        uv, vis = cam.project(tcp)
        tcp_uv[a], tcp_visible[a] = uv, vis
        n = ends.shape[1]
        fx = float(cam.K[0, 0])
        for t in range(T):
            for i in range(n):
                d = proj.depth[t, i]
                if d.min() < 0.05:  # behind or at the camera: the head camera looks down, so never in practice
                    continue
                p0, p1 = proj.uv[t, i]
                r0, r1 = fx * radii[i] / float(d[0]), fx * radii[i] / float(d[1])
                _capsule(whole[t], p0, p1, r0, r1)
                if i >= first_distal:
                    _capsule(distal[a, t], p0, p1, r0, r1)
                if i >= n - 4:  # last wrist housing + coupling, palm, fingers
                    _capsule(gripper[a, t], p0, p1, r0, r1)
    return ArmViews(whole=whole, distal=distal, gripper=gripper, tcp_uv=tcp_uv, tcp_visible=tcp_visible)


_SHIFT = 4  # cv2 fixed-point bits for sub-pixel end points
_ONE = 1 << _SHIFT


def _capsule(canvas: NDArray[np.uint8], p0: NDArray[np.float64], p1: NDArray[np.float64], r0: float, r1: float) -> None:
    """A capsule seen in perspective: discs of radii ``r0``, ``r1`` (pixels) at its ends and their hull."""
    lim = 4.0 * max(canvas.shape)  # keep far-off points inside cv2's coordinate range
    a = np.clip(p0, -lim, lim)
    b = np.clip(p1, -lim, lim)
    r0, r1 = min(r0, lim), min(r1, lim)
    for c, r in ((a, r0), (b, r1)):
        centre = (round(float(c[0]) * _ONE), round(float(c[1]) * _ONE))
        cv2.circle(canvas, centre, round(r * _ONE), 1, thickness=-1, lineType=cv2.LINE_8, shift=_SHIFT)
    d = b - a
    length = float(np.hypot(d[0], d[1]))
    if length < 1e-6:
        return
    n = np.array([-d[1], d[0]]) / length
    quad = np.stack([a + n * r0, b + n * r1, b - n * r1, a - n * r0])
    cv2.fillConvexPoly(canvas, np.round(quad * _ONE).astype(np.int32), 1, lineType=cv2.LINE_8, shift=_SHIFT)


# ---------------------------------------------------------------------- pixels


def channel_max(images: NDArray[Any]) -> NDArray[Any]:
    """``images.max(axis=-1)`` over the 3 colour channels, bit for bit, ~5× faster.

    NumPy reduces a length-3 last axis with a slow generic loop; two element-wise maxima are vectorised.
    The detector calls this on every frame of every view, so it was a sixth of a judged episode's time.
    """
    return np.asarray(np.maximum(np.maximum(images[..., 0], images[..., 1]), images[..., 2]))


def channel_min(images: NDArray[Any]) -> NDArray[Any]:
    """``images.min(axis=-1)`` over the 3 colour channels, bit for bit (see :func:`channel_max`)."""
    return np.asarray(np.minimum(np.minimum(images[..., 0], images[..., 1]), images[..., 2]))


@dataclass(frozen=True)
class TableColour:
    """The table's chromaticity ``(r, g, b) / (r + g + b)`` and brightness (max channel), from one frame."""

    chroma: tuple[float, float, float]
    value: float

    @staticmethod
    def default() -> TableColour:
        # TABLE_RGBA of the simulated rig (0.75, 0.72, 0.65) under its white key light.
        s = 0.75 + 0.72 + 0.65
        return TableColour((0.75 / s, 0.72 / s, 0.65 / s), 200.0)


def learn_table(image: Image, exclude: Mask) -> TableColour:
    """The table colour of ``image`` from its pixels outside ``exclude`` (predicted arms, objects)."""
    im = image.reshape(-1, 3).astype(np.float32)
    keep = ~exclude.reshape(-1)
    v = im.max(axis=1)
    keep &= v > 60  # the table edge, floor and slot outlines are far darker than the lit table
    if keep.sum() < 50:
        return TableColour.default()
    px = im[keep]
    s = px.sum(axis=1, keepdims=True) + 1e-6
    chroma = np.median(px / s, axis=0)
    return TableColour((float(chroma[0]), float(chroma[1]), float(chroma[2])), float(np.median(v[keep])))


def table_mask(images: Image, table: TableColour, *, max_chroma_distance: float = 0.018) -> Mask:
    """``(..., H, W)`` True where ``images`` ``(..., H, W, 3)`` look like the table (chromaticity and brightness).

    The grey arms are ~0.03 away from the table's chromaticity (bluer) and the grippers far darker; the
    table's own shading stays within ~0.008.
    """
    im = images.astype(np.float32)
    s = im.sum(axis=-1) + 1e-6
    ref = np.asarray(table.chroma, dtype=np.float32)
    dist = channel_max(np.abs(im / s[..., None] - ref))
    out: Mask = (dist <= max_chroma_distance) & (channel_max(im) >= 0.55 * table.value)
    return out


@dataclass(frozen=True, eq=False)
class Background:
    """The empty scene in the head view, learnt from the episode itself (what no arm and no object covers).

    ``image`` is the start frame where it shows the scene empty, elsewhere each pixel's median over the
    first few frames where no arm is predicted near it and no object is seen on it (blurred, float):
    textures, shading and fixed shadows included, so a textured table under
    a tinted light is explained pixel by pixel where one table colour cannot be. ``known``: pixels seen
    empty in at least a few frames; ``arm_free``: pixels some frames show without an arm (an idle arm's
    pixels never are, and say nothing about the table there).
    """

    image: NDArray[np.float32]  # (H, W, 3)
    known: Mask  # (H, W)
    arm_free: Mask  # (H, W)


BACKGROUND_MIN_FREE = 3  # frames a pixel must be seen empty in before its background counts as known
BACKGROUND_MAX_FRAMES = 48  # frames sampled for the median (memory and time at larger images)


def smooth(images: NDArray[np.uint8], sigma_px: float) -> NDArray[np.float32]:
    """Gaussian blur of every frame ``(..., H, W, 3)`` as float: camera noise and compression out of comparisons."""
    flat = images.reshape((-1, *images.shape[-3:]))
    out = np.stack([cv2.GaussianBlur(f.astype(np.float32), (0, 0), sigmaX=sigma_px) for f in flat])
    return out.reshape(images.shape).astype(np.float32)


def empty_pixels(arms: NDArray[np.uint8], objects: Mask, margin_px: float) -> tuple[Mask, Mask]:
    """``(T, H, W)`` pixels with no arm drawn within ``margin_px``, and of those the ones with no object seen
    within it either: what each frame shows of the empty scene (:func:`learn_background`, :func:`shadow_tint`)."""
    no_arm = np.stack([~dilate(a, margin_px) for a in arms])
    empty: Mask = no_arm & ~np.stack([dilate(o, margin_px) for o in objects])
    return no_arm, empty


def learn_background(blurred: NDArray[np.float32], no_arm: Mask, empty: Mask) -> Background:
    """:class:`Background` of ``blurred`` frames ``(T, H, W, 3)`` from their :func:`empty_pixels`."""
    T = blurred.shape[0]
    pick = np.unique(np.linspace(0, T - 1, min(T, BACKGROUND_MAX_FRAMES)).round().astype(int))
    free = empty[pick]
    # The earliest frames that show a pixel empty: the start is real in both branches, and a later stretch
    # of wrong frames (a swapped view, a world model's drift) must not become the "empty scene".
    known = free.sum(axis=0) >= BACKGROUND_MIN_FREE
    first = np.argsort(~free, axis=0, kind="stable")[:BACKGROUND_MIN_FREE]  # (3, H, W): free frames first, in order
    values = np.take_along_axis(blurred[pick], first[..., None], axis=0)  # (3, H, W, 3)
    image = np.median(values, axis=0).astype(np.float32)
    image[~known] = 0.0
    # Where the start frame itself shows the scene empty, it is the background.
    start = free[0] if pick[0] == 0 else np.zeros(known.shape, bool)
    image[start] = blurred[0][start]
    known |= start
    arm_free = (no_arm[pick].sum(axis=0) >= BACKGROUND_MIN_FREE) | start
    return Background(image=image, known=known, arm_free=arm_free)


def background_table(
    blurred: NDArray[np.float32], background: Background, colour_rule: Mask, *, max_difference: float
) -> Mask:
    """``(T, H, W)`` pixels the empty scene explains: within ``max_difference`` levels (any channel) of the
    background where it is known; where only objects ever covered a pixel, the table-colour rule
    (``colour_rule``, :func:`table_mask`); where an arm always was, never (nothing says what is under it)."""
    out: Mask = channel_max(np.abs(blurred - background.image[None])) <= max_difference
    out[:, ~background.known] = False
    fallback = ~background.known & background.arm_free
    out[:, fallback] = colour_rule[:, fallback]
    return out


def ratio_chroma(blurred: NDArray[np.float32], background: Background) -> tuple[NDArray[Any], NDArray[Any]]:
    """Per pixel of ``blurred`` ``(T, H, W, 3)``, the chromaticity of the per-channel ratio frame / empty scene
    (of its inverse where the frame is brighter) and the brightness ratio. A shadow scales every channel by the
    light it takes away, so within one episode all shadows share one ratio chromaticity: the tint of what
    light is left."""
    return colour_ratio(blurred, background.image[None])


def colour_ratio(now: NDArray[Any], before: NDArray[Any]) -> tuple[NDArray[Any], NDArray[Any]]:
    """:func:`ratio_chroma` of colours ``now`` against ``before`` (``(..., 3)``, broadcast)."""
    q = (now + 2.0) / (before + 2.0)
    bright = q.mean(axis=-1)
    q = np.where((bright > 1.0)[..., None], 1.0 / q, q)
    return q / q.sum(axis=-1, keepdims=True), bright


# The share of empty pixel-frames darkened before a scene counts as shadowed: the flat look has ≤ 0.0001; the
# varied look mostly ≥ 0.002, but where its shadows fall within a few pixels of the arms (which are not "empty")
# as little as 0.0002, and an unlearnt tint leaves those shadows to count as arm.
SHADOW_MIN_SHARE = 0.00015


@dataclass(frozen=True)
class Shadows:
    """What this episode's cast shadows do to the empty scene: the ratio chromaticity they share (the tint of
    the light left in them, see :func:`ratio_chroma`) and their typical brightness ratio (the light left:
    on a flat table nearly the same everywhere, 0.5–0.6 on the varied look)."""

    tint: NDArray[np.float64]  # (3,)
    ratio: float


def shadow_tint(
    chroma: NDArray[Any], bright: NDArray[Any], background: Background, empty: Mask, frames: int
) -> Shadows | None:
    """This episode's :class:`Shadows` from its :func:`ratio_chroma` and :func:`empty_pixels`: medians over the
    empty pixels that are darker than the empty scene, in the first ``frames`` frames or, where those hold too
    few, the first that hold enough (8 frames more at a time); None where the whole episode holds too few (a
    scene without cast shadows, such as the flat look).

    The light is the episode's, so its first frames tell it; a later stretch of wrong frames (a swapped view, a
    world model's drift) would shift the median and leave the true shadows unexplained, before that stretch too.
    """
    T = chroma.shape[0]
    free = empty & background.known[None]
    dark = free & (bright >= 0.2) & (bright <= 0.85)
    n_free = np.cumsum(free.sum(axis=(1, 2)))  # pixels counted in the first t + 1 frames
    n_dark = np.cumsum(dark.sum(axis=(1, 2)))
    n = min(max(frames, 1), T)
    while n_dark[n - 1] < max(SHADOW_MIN_SHARE * int(n_free[n - 1]), 50):
        if n >= T:
            return None
        n = min(n + 8, T)
    return Shadows(
        tint=np.asarray(np.median(chroma[:n][dark[:n]], axis=0), dtype=np.float64),
        ratio=float(np.median(bright[:n][dark[:n]])),
    )


def shadow_like(
    chroma: NDArray[Any],
    bright: NDArray[Any],
    background: Background,
    shadows: Shadows | None,
    *,
    max_distance: float,
    ratio_factor: float,
) -> Mask:
    """``(T, H, W)`` pixels that are the empty scene in a shadow cast or lifted (from :func:`ratio_chroma`): the
    ratio chromaticity within ``max_distance`` of the shadows' tint, the brightness scaled by the shadows'
    ratio (or its inverse, a shadow lifted) to within a factor ``ratio_factor``.

    A moving arm's shadow falls outside its drawn silhouette and is no arm. On the varied look a shadow lies
    ~0.01 from the tint (up to ~0.023 where two lights overlap) and a grey arm over wood 0.03–0.045; over a
    grey laminate an arm has the shadows' chromaticity, and only the brightness band tells them apart (about
    a third of such arm pixels fall in it)."""
    if shadows is None:
        return np.zeros(bright.shape, bool)  # no cast shadows in this scene: nothing to excuse
    out: Mask = background.known[None] & shadow_fit(
        chroma, bright, shadows, max_distance=max_distance, ratio_factor=ratio_factor
    )
    return out


def shadow_fit(
    chroma: NDArray[Any], bright: NDArray[Any], shadows: Shadows, *, max_distance: float, ratio_factor: float
) -> NDArray[np.bool_]:
    """Where a :func:`colour_ratio` is a shadow cast or lifted (see :func:`shadow_like`), whatever its shape."""
    lo, hi = shadows.ratio / ratio_factor, min(shadows.ratio * ratio_factor, 0.97)
    close = channel_max(np.abs(chroma - shadows.tint.astype(np.float32))) <= max_distance
    cast = (bright >= lo) & (bright <= hi)
    lifted = (bright >= 1.0 / hi) & (bright <= 1.0 / lo)
    return np.asarray(close & (cast | lifted))


def object_labels(images: Image, classes: list[ColourClass], faded_saturation: float = 0.22) -> NDArray[np.uint8]:
    """``(T, H, W)`` 0 = no object, ``i + 1`` = ``classes[i]``, for ``images`` ``(T, H, W, 3)``.

    The scripted policies' colour test (saturation ≥ 0.35) but with value ≥ 0.2 instead of 0.12 (video
    compression leaves strongly tinted one-pixel seams, value ~0.13, along the edges of dark grippers on
    the table; the objects' darkest shaded faces stay above 0.2), plus *faded* pixels: bright (value ≥ 0.45)
    with saturation ≥ ``faded_saturation``. World-model frames wash colours out, and a faded object is
    still an object; the table's own saturation stays below 0.16 in 99 % of its pixels. The brightness
    floor keeps out the anti-aliased edges of dark things on the table, whose saturation grows as their
    value falls.
    """
    out = np.zeros(images.shape[:3], np.uint8)
    if not classes:
        return out
    for t in range(images.shape[0]):
        masks = segment(images[t], classes, min_value=0.2)
        faded = segment(images[t], classes, min_saturation=faded_saturation, min_value=0.45)
        for i, c in enumerate(classes):
            out[t][masks[c.name] | faded[c.name]] = i + 1
    return out


TEXTURE_FRAMES = 3  # start frames (real in both branches) in which a colour's specks mark it as texture


def table_texture(
    images: Image,
    classes: list[ColourClass],
    arms: NDArray[np.uint8],
    *,
    faded_saturation: float = 0.22,
    ratio: float = 1.0,
    specks: int = 3,
    scale: float = 1.0,
) -> list[bool]:
    """Per class, whether it is the table's own texture rather than an object, from start frames ``images``
    ``(T, H, W, 3)`` with the arms drawn in ``arms`` ``(T, H, W)``.

    A warm wood table's grains have an object's hue: they pass :func:`object_labels`' faded test (bright,
    saturation ≥ ``faded_saturation``) and now and then a pixel or two its full test, so the colour is
    discovered, and its specks come and go with camera noise and shadows. An object is a compact blob of
    fully saturated pixels with a faded rim. So a class whose faded pixels away from its own saturated ones
    (beyond a rim of 3 px) outnumber those saturated pixels ``ratio`` times over, in ``specks`` or more specks,
    over the start frames (real in both branches), is texture: measured at seeds 4,600,000+ (every third
    episode), texture classes had 1.1-490 times more speck pixels than saturated ones in 3-29 specks; object
    classes up to 8 times, but in at most 2 specks.
    """
    if not classes:
        return []
    strict = [segment(im, classes, min_value=0.2) for im in images]
    faded = [segment(im, classes, min_saturation=faded_saturation, min_value=0.45) for im in images]
    away = [~dilate(a, 2 * scale) for a in arms]
    rim = 3.0 * scale
    out: list[bool] = []
    for c in classes:
        solid = speckle = count = 0
        for t in range(len(images)):
            s = strict[t][c.name] & away[t]
            f = faded[t][c.name] & away[t] & ~dilate(s, rim)
            solid += int(s.sum())
            speckle += int(f.sum())
            n, _ = cv2.connectedComponents(f.astype(np.uint8), connectivity=8)
            count = max(count, n - 1)
        out.append(count >= specks and speckle >= ratio * max(solid, 1))
    return out


def without_table_texture(
    images: Image,
    classes: list[ColourClass],
    arms: NDArray[np.uint8],
    *,
    frames: int = TEXTURE_FRAMES,
    faded_saturation: float = 0.22,
    ratio: float = 1.0,
    specks: int = 3,
    scale: float = 1.0,
) -> list[ColourClass]:
    """``classes`` less those :func:`table_texture` finds to be the table's texture in the first ``frames`` of
    ``images`` ``(T, H, W, 3)`` (arms drawn in ``arms`` ``(T, H, W)``): the object colours, for the detector and
    the fault injection alike."""
    n = min(frames, len(images))
    grain = table_texture(
        images[:n], classes, arms[:n], faded_saturation=faded_saturation, ratio=ratio, specks=specks, scale=scale
    )
    return [c for c, texture in zip(classes, grain, strict=True) if not texture]


def colourful_mask(images: Image, min_saturation: float = 0.3, min_value: float = 0.2) -> Mask:
    """``(..., H, W)`` True for saturated pixels of any hue (``images`` ``(..., H, W, 3)`` RGB): objects.

    The arms (saturation ~0.05), grippers and table (~0.13) never pass; compression seams along dark
    edges are kept out by the value floor.
    """
    im = images.astype(np.int16)
    mx = channel_max(im)
    mn = channel_min(im)
    out: Mask = (mx - mn >= min_saturation * mx) & (mx >= min_value * 255)
    return out


def convex_hull(mask: NDArray[np.bool_]) -> Mask:
    """Each 8-connected part of ``mask`` filled to its convex hull (empty stays empty): a gripper's fingers
    and what they hold between them, without bridging to a separate dark patch (the arm's own shadow)."""
    m = np.asarray(mask, np.uint8)
    out = np.zeros(m.shape, np.uint8)
    n, labels = cv2.connectedComponents(m, connectivity=8)
    for i in range(1, n):
        pts = cv2.findNonZero((labels == i).astype(np.uint8))
        cv2.fillConvexPoly(out, cv2.convexHull(pts), 1)
    return out.astype(bool)


def disk(radius_px: float) -> NDArray[np.uint8]:
    """A filled disc structuring element of the given radius (at least a single pixel)."""
    r = max(0, round(radius_px))
    return np.asarray(cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (2 * r + 1, 2 * r + 1)), dtype=np.uint8)


def dilate(mask: NDArray[np.bool_] | NDArray[np.uint8], radius_px: float) -> Mask:
    m = np.ascontiguousarray(mask, dtype=np.uint8)
    if radius_px < 0.5:
        return m.astype(bool)
    return cv2.dilate(m, disk(radius_px)).astype(bool)


def erode(mask: NDArray[np.bool_] | NDArray[np.uint8], radius_px: float) -> Mask:
    m = np.ascontiguousarray(mask, dtype=np.uint8)
    if radius_px < 0.5:
        return m.astype(bool)
    return cv2.erode(m, disk(radius_px)).astype(bool)


def head_camera(rig: RigConfig) -> CameraModel:
    return rig.head_camera_model
