"""Tests for calib.board (config, layout, PNG) and calib.pdf (true-scale page)."""

from __future__ import annotations

import math
import re
import struct
from pathlib import Path

import cv2
import numpy as np
import pytest
import yaml

from calib.board import BOARD_FORMAT, METRES_PER_INCH, ChArUcoBoard
from calib.detect import BoardDetector

from .scenes import A3, A4

PT_PER_M = 72.0 / METRES_PER_INCH


def test_shipped_configs_load() -> None:
    a4 = ChArUcoBoard.from_yaml(A4)
    assert (a4.squares_x, a4.squares_y, a4.name) == (7, 5, "charuco_7x5_a4")
    w, h = a4.page_size_m
    assert w <= 0.297 - 0.02 and h <= 0.210 - 0.01  # fits A4 landscape with printer margins
    a3 = ChArUcoBoard.from_yaml(A3)
    assert a3.n_corners == 88 and a3.page_size_m[0] <= 0.420 - 0.02 and a3.page_size_m[1] <= 0.297 - 0.01


@pytest.mark.parametrize(
    ("change", "message"),
    [
        ({"marker_length_m": 0.035}, "marker_length_m"),
        ({"squares_x": 2}, "squares_x"),
        ({"squares_y": 4.5}, "squares_y"),
        ({"dictionary": "DICT_5X5_101"}, "unknown 'DICT_5X5_101'"),
        ({"dictionary": "DICT_4X4_50", "squares_x": 12, "squares_y": 9}, "has 50 markers but a 12x9 board needs 54"),
        ({"legacy_pattern": "yes"}, "legacy_pattern"),
        ({"margin_m": -0.01}, "margin_m"),
        ({"colour": "red"}, "unknown field(s) 'colour'"),
        ({"format": "v0"}, "field 'format'"),
    ],
)
def test_invalid_config_names_the_field(tmp_path: Path, change: dict[str, object], message: str) -> None:
    data = yaml.safe_load(A4.read_text()) | change
    path = tmp_path / "bad.yaml"
    path.write_text(yaml.safe_dump(data))
    with pytest.raises(ValueError, match=re.escape(message)) as info:
        ChArUcoBoard.from_yaml(path)
    assert str(path) in str(info.value)


def test_missing_field_and_file(tmp_path: Path) -> None:
    with pytest.raises(ValueError, match="'square_length_m': missing"):
        ChArUcoBoard.from_dict({"format": BOARD_FORMAT, "squares_x": 5, "squares_y": 5})
    with pytest.raises(FileNotFoundError, match=r"nope\.yaml"):
        ChArUcoBoard.from_yaml(tmp_path / "nope.yaml")


def test_corner_points_match_opencv() -> None:
    board = ChArUcoBoard.from_yaml(A3)
    ours = board.corner_points()
    theirs = np.asarray(board.cv_board().getChessboardCorners(), dtype=np.float64)
    np.testing.assert_allclose(ours, theirs, atol=1e-7)  # OpenCV keeps float32


@pytest.mark.parametrize("legacy", [False, True])
def test_layout_matches_opencv_generate_image(legacy: bool) -> None:
    # An even number of rows, where the two layouts differ.
    board = ChArUcoBoard(8, 6, 0.03, 0.022, "DICT_5X5_100", legacy_pattern=legacy)
    ours = board.render(4000.0, margin_m=0.0)
    ref = board.cv_board().generateImage((ours.shape[1], ours.shape[0]), marginSize=0, borderBits=1)
    # OpenCV resizes markers drawn at integer cell sizes, so edges may move by a pixel; nothing else may differ.
    edge = cv2.dilate(ours, np.ones((3, 3))) != cv2.erode(ours, np.ones((3, 3)))
    differ = ours != ref
    assert differ.mean() < 0.01
    assert not np.any(differ & ~edge)


def test_antialiased_render_keeps_the_black_area() -> None:
    board = ChArUcoBoard.from_yaml(A4)
    area = sum((x1 - x0) * (y1 - y0) for x0, y0, x1, y1 in board.black_rectangles())
    ppm = 1234.5  # deliberately not a divisor of any length
    img = board.render(ppm, antialias=True)
    black_px = float((255.0 - img.astype(np.float64)).sum() / 255.0)
    assert black_px == pytest.approx(area * ppm**2, rel=2e-3)


def _pdf_page_and_rects(path: Path) -> tuple[list[float], list[tuple[float, ...]]]:
    text = path.read_bytes().decode("latin-1")
    box = re.search(r"/MediaBox \[([^\]]*)\]", text)
    assert box is not None
    rects = [tuple(float(v) for v in m.groups()) for m in re.finditer(r"(\S+) (\S+) (\S+) (\S+) re\b", text)]
    return [float(v) for v in box.group(1).split()], rects


def test_pdf_page_is_the_physical_board_size(tmp_path: Path) -> None:
    board = ChArUcoBoard.from_yaml(A4)
    w_pt, h_pt = board.write_pdf(tmp_path / "b.pdf")
    box, rects = _pdf_page_and_rects(tmp_path / "b.pdf")
    # 7 x 35 mm + 2 x 10 mm = 265 mm wide, 5 x 35 mm + 20 mm = 195 mm high.
    assert box == pytest.approx([0.0, 0.0, 0.265 * PT_PER_M, 0.195 * PT_PER_M], abs=1e-3)
    assert (w_pt, h_pt) == pytest.approx((751.1811, 552.7559), abs=1e-3)
    assert len(rects) == len(board.black_rectangles())
    # The top-left black square of the post-4.6 layout: 35 mm at (10 mm, 10 mm) from the top-left corner.
    sq = 0.035 * PT_PER_M
    assert (0.01 * PT_PER_M, h_pt - 0.01 * PT_PER_M - sq, sq, sq) == pytest.approx(_first_square(rects, sq), abs=1e-3)


def test_pdf_cross_reference_table_is_valid(tmp_path: Path) -> None:
    ChArUcoBoard.from_yaml(A3).write_pdf(tmp_path / "b.pdf")
    data = (tmp_path / "b.pdf").read_bytes()
    assert data.startswith(b"%PDF-1.4") and data.rstrip().endswith(b"%%EOF")
    start = int(data.rsplit(b"startxref", 1)[1].split()[0])
    assert data[start:].startswith(b"xref\n0 6\n")
    entries = data[start:].split(b"\n")[3:8]
    for number, entry in enumerate(entries, start=1):
        offset = int(entry.split()[0])
        assert data[offset:].startswith(f"{number} 0 obj".encode()), number
    length = int(re.search(rb"/Length (\d+)", data).group(1))  # type: ignore[union-attr]
    stream_start = data.index(b"stream\n") + len(b"stream\n")
    assert data[stream_start + length :].startswith(b"endstream")


def _first_square(rects: list[tuple[float, ...]], side: float) -> tuple[float, ...]:
    squares = [r for r in rects if abs(r[2] - side) < 1e-3 and abs(r[3] - side) < 1e-3]
    return max(squares, key=lambda r: (r[1], -r[0]))  # highest, then leftmost


def test_pdf_rectangles_rasterise_to_the_png(tmp_path: Path) -> None:
    board = ChArUcoBoard.from_yaml(A4)
    board.write_pdf(tmp_path / "b.pdf")
    box, rects = _pdf_page_and_rects(tmp_path / "b.pdf")
    ppm = 2999.0  # no edge falls exactly on a pixel centre, where the PDF's 1e-4 pt rounding could flip it
    png = board.render(ppm)
    raster = np.full_like(png, 255)
    scale = ppm / PT_PER_M
    height = box[3] * scale  # the page height in pixels (not rounded: the image is cut at the bottom)
    for x, y, w, h in rects:
        u0, u1 = math.ceil(x * scale - 0.5), math.ceil((x + w) * scale - 0.5)
        v0, v1 = math.ceil(height - (y + h) * scale - 0.5), math.ceil(height - y * scale - 0.5)
        raster[v0:v1, u0:u1] = 0
    np.testing.assert_array_equal(raster, png)


def test_png_has_physical_resolution_and_is_detectable(tmp_path: Path) -> None:
    board = ChArUcoBoard.from_yaml(A4)
    width, height = board.write_png(tmp_path / "b.png", dpi=150)
    data = (tmp_path / "b.png").read_bytes()
    i = data.index(b"pHYs")
    ppx, ppy, unit = struct.unpack(">IIB", data[i + 4 : i + 13])
    assert unit == 1 and ppx == ppy == round(150 / METRES_PER_INCH)
    image = cv2.imread(str(tmp_path / "b.png"), cv2.IMREAD_GRAYSCALE)
    assert image is not None and image.shape == (height, width) == (
        round(0.195 * 150 / 0.0254),
        round(0.265 * 150 / 0.0254),
    )
    det = BoardDetector(board).detect(image)
    assert det.n_corners == board.n_corners
