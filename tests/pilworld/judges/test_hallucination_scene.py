"""The detector's empty-scene model: learnt per pixel from the frames where nothing covers a pixel, it explains
a textured table and shadows where one table colour cannot, and says nothing under an arm that never moves."""

from __future__ import annotations

import numpy as np

from pilworld.judges.hallucination_scene import (
    SHADOW_MIN_SHARE,
    Background,
    Shadows,
    TableColour,
    background_table,
    empty_pixels,
    learn_background,
    ratio_chroma,
    shadow_like,
    shadow_tint,
    smooth,
    table_mask,
)

T, H, W = 12, 32, 48


def _scene() -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A wood-grain-like grey table, an arm (flat grey bar) sweeping left to right, an idle arm at the right edge."""
    rng = np.random.default_rng(0)
    u = np.arange(W)[None, :]
    v = np.arange(H)[:, None]
    grain = 150 + 25 * np.sin(u / 3.0 + 0.4 * np.sin(v / 5.0)) + rng.normal(0, 2, (H, W))
    table = np.clip(np.stack([grain * 1.0, grain * 0.96, grain * 0.88], axis=-1), 0, 255)
    images = np.repeat(table[None], T, axis=0)
    arms = np.zeros((T, H, W), np.uint8)
    for t in range(T):
        x0 = 2 + 3 * t
        arms[t, 10:20, x0 : x0 + 6] = 1  # the moving arm, drawn where the state puts it
        arms[t, :, W - 5 :] = 1  # the idle arm: never moves, so its pixels are never seen empty
        images[t, 10:20, x0 : x0 + 6] = (148, 150, 155)  # a grey arm as bright as the table
        images[t, :, W - 5 :] = (60, 62, 66)
    return images.astype(np.uint8), arms, np.zeros((T, H, W), bool)


def _background(blurred: np.ndarray, arms: np.ndarray, objects: np.ndarray) -> Background:
    return learn_background(blurred, *empty_pixels(arms, objects, margin_px=1))


def test_the_empty_scene_is_learnt_where_nothing_covers_it_and_unknown_under_an_idle_arm() -> None:
    images, arms, objects = _scene()
    blurred = smooth(images, 0.5)
    bg = _background(blurred, arms, objects)
    assert bg.known[:, :30].all()  # the swept band is empty in most frames
    assert not bg.known[:, W - 3 :].any() and not bg.arm_free[:, W - 3 :].any()
    # the learnt image is the table, not the arm that passed over it
    assert np.abs(bg.image[12:18, 10:20] - blurred[0, 12:18, 10:20]).max() < 6


def test_the_arm_is_not_table_and_the_textured_table_is() -> None:
    images, arms, objects = _scene()
    blurred = smooth(images, 0.5)
    bg = _background(blurred, arms, objects)
    # one table colour, the arm's own, would call everything table
    colour = TableColour((0.329, 0.333, 0.338), 150.0)
    assert table_mask(images[:1, 10:20, 2:8], colour).all()
    table = background_table(blurred, bg, table_mask(images, colour), max_difference=10.0)
    t = 5
    inner = np.zeros((H, W), bool)
    inner[11:19, 3 + 3 * t : 3 + 3 * t + 4] = True
    assert not table[t][inner].any()  # the arm differs from the table under it, though as bright
    free = ~np.pad(arms[t].astype(bool), 2)[2:-2, 2:-2] & bg.known
    free[10:20] = False
    assert table[t][free].mean() > 0.98
    assert not table[:, :, W - 3 :].any()  # under the idle arm: no evidence of table, whatever the colour rule says


def test_a_shadow_is_the_table_darker_and_a_differently_coloured_thing_is_not() -> None:
    images, arms, objects = _scene()
    shadowed = images.copy().astype(np.float64)
    tint = np.array([0.95, 1.0, 1.1])  # what the ambient light left is bluer than the key light
    for t in range(1, T):
        x0 = 3 * t  # each frame the arm's shadow falls to the left of it, tinted
        shadowed[t, 22:30, max(x0 - 2, 0) : x0 + 6] *= 0.5 * tint
    shadowed[6, 2:7, 30:36] = (40, 90, 160)  # something blue
    blurred = smooth(np.clip(shadowed, 0, 255).astype(np.uint8), 0.5)
    bg = _background(blurred, arms, objects)
    _, empty = empty_pixels(arms, objects, margin_px=1)
    found = shadow_tint(*ratio_chroma(blurred, bg), bg, empty, T)
    assert found is not None
    assert np.abs(found.tint - tint / tint.sum()).max() < 0.01
    assert abs(found.ratio - 0.5 * tint.mean()) < 0.03
    shadow = shadow_like(*ratio_chroma(blurred, bg), bg, found, max_distance=0.02, ratio_factor=1.35)
    assert shadow[6, 23:29, 17:23].mean() > 0.95
    assert not shadow[6, 3:6, 31:35].any()
    grey = blurred.copy()
    grey[6, 2:8, 10:16] *= 0.9 * tint / tint.mean()  # the shadows' tint but hardly darker: not a shadow of this light
    assert not shadow_like(*ratio_chroma(grey, bg), bg, found, max_distance=0.02, ratio_factor=1.35)[
        6, 3:7, 11:15
    ].any()
    no_tint = shadow_like(*ratio_chroma(blurred, bg), bg, None, max_distance=0.02, ratio_factor=1.35)
    assert not no_tint.any()  # no shadows learnt


def test_the_shadow_tint_is_the_first_frames_light() -> None:
    """A later stretch of wrong frames (a swapped view, a world model's drift) darkens the scene in another tint;
    learnt over the whole episode it would pull the median away and leave the true shadows unexplained."""
    images, arms, objects = _scene()
    shadowed = images.copy().astype(np.float64)
    tint, wrong = np.array([0.95, 1.0, 1.1]), np.array([1.2, 1.0, 0.7])
    for t in range(1, T):
        x0 = 3 * t
        shadowed[t, 22:30, max(x0 - 2, 0) : x0 + 6] *= 0.5 * (tint if t < T // 2 else wrong)
        if t >= T // 2:
            shadowed[t, 2:9, :] *= 0.6 * wrong  # and much more of it
    blurred = smooth(np.clip(shadowed, 0, 255).astype(np.uint8), 0.5)
    bg = _background(blurred, arms, objects)
    _, empty = empty_pixels(arms, objects, margin_px=1)
    chroma, bright = ratio_chroma(blurred, bg)
    first = shadow_tint(chroma, bright, bg, empty, T // 2)
    assert first is not None and np.abs(first.tint - tint / tint.sum()).max() < 0.01
    whole = shadow_tint(chroma, bright, bg, empty, T)
    assert whole is not None and np.abs(whole.tint - tint / tint.sum()).max() > 0.02


def test_a_scene_without_cast_shadows_has_no_tint() -> None:
    images, arms, objects = _scene()
    blurred = smooth(images, 0.5)
    bg = _background(blurred, arms, objects)
    _, empty = empty_pixels(arms, objects, margin_px=1)
    assert shadow_tint(*ratio_chroma(blurred, bg), bg, empty, T) is None


def test_a_scene_with_few_cast_shadows_still_learns_their_tint() -> None:
    """Where an arm's shadow falls mostly within a few pixels of the arm, only a few hundred empty pixel-frames
    are darkened (0.02–0.1 % on the varied look's fresh scenes); their tint is still the light's, and the
    flat look's stray darkened pixels (≤ 0.01 %) still make no tint."""
    rng = np.random.default_rng(1)
    n, side = 48, 128
    table = np.clip(150 + rng.normal(0, 2, (side, side, 1)) * np.ones(3), 0, 255)
    tint = np.array([0.95, 1.0, 1.1])
    arms = np.zeros((n, side, side), np.uint8)
    objects = np.zeros((n, side, side), bool)

    def darkened(patch: int) -> tuple[float, Shadows | None]:
        images = np.repeat(table[None], n, axis=0)
        for t in range(4, n, 2):  # after the first frames (the empty scene is learnt from those)
            images[t, 60 : 60 + patch, 60 : 60 + patch] *= 0.5 * tint
        blurred = smooth(np.clip(images, 0, 255).astype(np.uint8), 0.5)
        bg = _background(blurred, arms, objects)
        _, empty = empty_pixels(arms, objects, margin_px=1)
        chroma, bright = ratio_chroma(blurred, bg)
        dark = empty & (bright >= 0.2) & (bright <= 0.85)
        return float(dark.sum() / empty.sum()), shadow_tint(chroma, bright, bg, empty, n)

    share, found = darkened(4)
    assert SHADOW_MIN_SHARE < share < 0.001
    assert found is not None and np.abs(found.tint - tint / tint.sum()).max() < 0.01
    share, found = darkened(1)
    assert share < SHADOW_MIN_SHARE and found is None


def test_a_colour_in_faint_specks_all_over_the_table_is_its_texture() -> None:
    """A wood table's grains (faded warm specks) are texture; an object (a saturated blob, its faded rim) is not."""
    import colorsys

    from pilworld.judges.hallucination_scene import table_texture
    from pilworld.perception.colour import ColourClass

    def rgb(hue_deg: float, sat: float, val: float) -> tuple[int, int, int]:
        r, g, b = colorsys.hsv_to_rgb(hue_deg / 360.0, sat, val)
        return round(255 * r), round(255 * g), round(255 * b)

    image = np.full((3, 64, 64, 3), 120, np.uint8)
    image[:, 30:40, 30:40] = rgb(200, 0.25, 0.8)  # the object's faded rim …
    image[:, 32:38, 32:38] = rgb(200, 0.9, 0.8)  # … around its saturated body
    for k in range(6):  # grains of another hue, faded, spread over the table
        image[:, 4 + 9 * k : 6 + 9 * k, 4:8] = rgb(30, 0.25, 0.8)
    classes = [ColourClass("blue", colorsys.hsv_to_rgb(200 / 360, 1, 1)), ColourClass("wood", (1.0, 0.5, 0.0))]
    arms = np.zeros(image.shape[:3], np.uint8)
    assert table_texture(image, classes, arms) == [False, True]
    image[:, 4:6, 4:8] = rgb(30, 0.9, 0.8)  # one grain saturated: still far outnumbered
    assert table_texture(image, classes, arms) == [False, True]
    arms[:, :, :12] = 1  # an arm over the grains: no specks seen, no texture
    assert table_texture(image, classes, arms) == [False, False]
    assert table_texture(image, [], arms) == []
