"""Object colours found in images: compact saturated blobs count, scattered saturated specks (texture) do not."""

from __future__ import annotations

import colorsys

import numpy as np
import pytest

from pilworld.perception.colour import segment
from pilworld.perception.objects import discover_colours, discover_colours_over


def _rgb(hue_deg: float, s: float = 0.9, v: float = 0.85) -> np.ndarray:
    return (np.array(colorsys.hsv_to_rgb(hue_deg / 360.0, s, v)) * 255).round().astype(np.uint8)


def _scene(seed: int = 0) -> np.ndarray:
    """A beige table with saturated orange specks everywhere (a sand texture), a red and a blue square."""
    rng = np.random.default_rng(seed)
    img = np.empty((128, 128, 3), np.uint8)
    img[:] = _rgb(40, 0.15, 0.8)
    specks = rng.random((128, 128)) < 0.04
    img[specks] = _rgb(30, 0.6, 0.8)
    img[20:30, 30:40] = _rgb(0)
    img[70:78, 90:98] = _rgb(210)
    return img


def _hues(classes: list) -> list[int]:
    return sorted(int(c.name.split("_")[1]) for c in classes)


def test_compact_blobs_are_objects_and_texture_is_not() -> None:
    img = _scene()
    found = discover_colours(img)
    assert len(found) == 2
    red, blue = sorted(found, key=lambda c: c.name)  # hue_000 … hue_210
    assert abs(int(red.name.split("_")[1]) - 0) <= 4 and abs(int(blue.name.split("_")[1]) - 210) <= 4
    masks = segment(img, found)  # the classes work as a palette
    assert masks[red.name][20:30, 30:40].all() and masks[blue.name][70:78, 90:98].all()


def test_the_bigger_object_comes_first_and_excluded_pixels_are_not_seen() -> None:
    img = _scene()
    assert _hues(discover_colours(img)[:1]) in ([0], [2], [358])  # the red square is the larger
    exclude = np.zeros((128, 128), bool)
    exclude[15:35, 25:45] = True  # an arm over the red square
    assert [c.name for c in discover_colours(img, exclude)] == [c.name for c in discover_colours(img)][1:]


def test_tiny_blobs_and_grey_scenes_give_nothing() -> None:
    img = np.full((128, 128, 3), 128, np.uint8)
    assert discover_colours(img) == []
    img[5:7, 5:7] = _rgb(120)  # 4 pixels: below the minimum
    assert discover_colours(img) == []


def test_colours_hidden_in_the_first_frame_are_found_in_later_ones() -> None:
    frames = np.stack([_scene(), _scene()])
    frames[0, 15:35, 25:45] = 100  # an arm over the red square at the start
    assert len(discover_colours(frames[0])) == 1
    assert _hues(discover_colours_over(frames)) == _hues(discover_colours(frames[1]))


@pytest.mark.parametrize("bad", [np.zeros((8, 8), np.uint8), np.zeros((8, 8, 3), np.float32)])
def test_bad_images_are_refused(bad: np.ndarray) -> None:
    with pytest.raises(ValueError, match="image"):
        discover_colours(bad)
