"""A printable ChArUco calibration board: its config, OpenCV object, exact layout and true-scale output.

Board frame (OpenCV's, ``cv2.aruco.CharucoBoard``): origin at the top-left outer corner of the chessboard
as printed, x to the right, y down, z into the board, metres. Chessboard corner ``k`` (the id that
``CharucoDetector`` returns) sits at ``((k % (squares_x - 1) + 1) s, (k // (squares_x - 1) + 1) s, 0)``
with ``s`` the square length.

Config file (``configs/board/*.yaml``; the same keys in :meth:`ChArUcoBoard.from_dict`)::

    format: pilworld.charuco_board/v1  # required, exactly this string
    name: charuco_7x5_a4               # optional, default: the file name without .yaml
    squares_x: 7                        # squares along x (columns), >= 3
    squares_y: 5                        # squares along y (rows), >= 3
    square_length_m: 0.035              # chessboard square side, metres
    marker_length_m: 0.026              # ArUco marker side, metres, < square_length_m
    dictionary: DICT_5X5_100            # cv2.aruco predefined dictionary name
    legacy_pattern: false               # OpenCV < 4.6 layout (matters only for an even squares_y)
    margin_m: 0.01                      # optional white quiet zone printed around the board, metres

The layout (:meth:`ChArUcoBoard.black_rectangles`) is computed exactly in metres from the OpenCV board,
so the PNG (rasterised at a DPI) and the PDF (vector rectangles, :mod:`calib.pdf`) print at true scale
whatever the resolution; only OpenCV's own ``generateImage`` is resolution-bound.
"""

from __future__ import annotations

import errno
import math
import struct
import zlib
from collections.abc import Mapping
from dataclasses import dataclass, replace
from functools import cached_property
from pathlib import Path
from typing import Any, Final

import cv2
import numpy as np
import numpy.typing as npt
import yaml

from calib.pdf import write_rectangles_pdf

__all__ = ["BOARD_FORMAT", "METRES_PER_INCH", "ChArUcoBoard", "Rect"]

FloatArray = npt.NDArray[np.float64]
UInt8Array = npt.NDArray[np.uint8]

#: Value of the ``format`` key of board files.
BOARD_FORMAT: Final = "pilworld.charuco_board/v1"
METRES_PER_INCH: Final = 0.0254

_KEYS: Final = (
    "format",
    "name",
    "squares_x",
    "squares_y",
    "square_length_m",
    "marker_length_m",
    "dictionary",
    "legacy_pattern",
    "margin_m",
)
_REQUIRED: Final = ("format", "squares_x", "squares_y", "square_length_m", "marker_length_m", "dictionary")

#: An axis-aligned black rectangle ``(x0, y0, x1, y1)`` in the board frame, metres (y down).
Rect = tuple[float, float, float, float]


def _dictionary_names() -> tuple[str, ...]:
    return tuple(sorted(n for n in dir(cv2.aruco) if n.startswith("DICT_")))


@dataclass(frozen=True, eq=True)
class ChArUcoBoard:
    """A ChArUco board description, validated on construction (``ValueError`` naming field and value)."""

    squares_x: int  #: squares along the board x axis (columns as printed), >= 3
    squares_y: int  #: squares along the board y axis (rows as printed), >= 3
    square_length_m: float  #: chessboard square side, metres
    marker_length_m: float  #: ArUco marker side, metres; strictly smaller than the square
    dictionary: str = "DICT_5X5_100"  #: name of a ``cv2.aruco`` predefined dictionary
    #: OpenCV < 4.6 marker layout. For an even ``squares_y`` the two layouts differ and a detector with the
    #: wrong one finds the markers but no corners (see :mod:`calib.detect`); for an odd one they are equal.
    legacy_pattern: bool = False
    margin_m: float = 0.01  #: white quiet zone around the board in the PNG/PDF, metres (>= 0)
    name: str = "charuco"  #: a label for reports and the PDF caption

    def __post_init__(self) -> None:
        for key in ("squares_x", "squares_y"):
            value = getattr(self, key)
            if isinstance(value, bool) or not isinstance(value, int | np.integer) or not 3 <= int(value) <= 200:
                raise ValueError(f"board field {key!r}: expected an integer in 3..200, got {value!r}")
            object.__setattr__(self, key, int(value))
        for key in ("square_length_m", "marker_length_m"):
            value = getattr(self, key)
            if isinstance(value, bool) or not isinstance(value, int | float) or not 0.0 < float(value) <= 1.0:
                raise ValueError(f"board field {key!r}: expected metres in (0, 1], got {value!r}")
            object.__setattr__(self, key, float(value))
        if not self.marker_length_m < self.square_length_m:
            raise ValueError(
                f"board field 'marker_length_m': must be smaller than square_length_m = {self.square_length_m!r}, "
                f"got {self.marker_length_m!r}"
            )
        margin = self.margin_m
        if isinstance(margin, bool) or not isinstance(margin, int | float) or not 0.0 <= float(margin) <= 1.0:
            raise ValueError(f"board field 'margin_m': expected metres in [0, 1], got {margin!r}")
        object.__setattr__(self, "margin_m", float(margin))
        if not isinstance(self.legacy_pattern, bool):
            raise ValueError(f"board field 'legacy_pattern': expected true or false, got {self.legacy_pattern!r}")
        if not isinstance(self.name, str) or not self.name.strip():
            raise ValueError(f"board field 'name': expected a non-empty string, got {self.name!r}")
        names = _dictionary_names()
        if self.dictionary not in names:
            raise ValueError(f"board field 'dictionary': unknown {self.dictionary!r}; allowed: {', '.join(names)}")
        n_markers = (self.squares_x * self.squares_y) // 2
        available = int(self.aruco_dictionary().bytesList.shape[0])
        if n_markers > available:
            raise ValueError(
                f"board field 'dictionary': {self.dictionary} has {available} markers but a "
                f"{self.squares_x}x{self.squares_y} board needs {n_markers}; use a larger dictionary"
            )

    # ------------------------------------------------------------------ loading

    @classmethod
    def from_dict(cls, d: Mapping[str, Any], source: str = "<dict>", default_name: str = "charuco") -> ChArUcoBoard:
        """Build a board from a config mapping (see the module docstring); errors name ``source``."""
        if not isinstance(d, Mapping):
            raise ValueError(f"{source}: expected a mapping with keys {', '.join(_KEYS)}, got {type(d).__name__}")
        unknown = [str(k) for k in d if k not in _KEYS]
        if unknown:
            raise ValueError(
                f"{source}: unknown field(s) {', '.join(repr(k) for k in unknown)}; allowed: {', '.join(_KEYS)}"
            )
        for key in _REQUIRED:
            if key not in d:
                raise ValueError(f"{source}: field {key!r}: missing (required: {', '.join(_REQUIRED)})")
        if d["format"] != BOARD_FORMAT:
            raise ValueError(f"{source}: field 'format': expected {BOARD_FORMAT!r}, got {d['format']!r}")
        kwargs = {k: d[k] for k in _KEYS if k in d and k != "format"}
        kwargs.setdefault("name", default_name)
        try:
            return cls(**kwargs)
        except ValueError as exc:
            raise ValueError(f"{source}: {exc}") from exc

    @classmethod
    def from_yaml(cls, path: str | Path) -> ChArUcoBoard:
        """Load ``configs/board/*.yaml``; ``FileNotFoundError`` with the path, ``ValueError`` naming the field."""
        path = Path(path)
        try:
            text = path.read_text(encoding="utf-8")
        except FileNotFoundError:
            raise FileNotFoundError(errno.ENOENT, "board config not found", str(path)) from None
        try:
            data = yaml.safe_load(text)
        except yaml.YAMLError as exc:
            raise ValueError(f"{path}: not valid YAML: {exc}") from exc
        return cls.from_dict(data if data is not None else {}, source=str(path), default_name=path.stem)

    def with_legacy_pattern(self, legacy: bool) -> ChArUcoBoard:
        """The same board with the other (or the given) marker layout."""
        return replace(self, legacy_pattern=legacy)

    # ------------------------------------------------------------------ OpenCV objects and geometry

    def aruco_dictionary(self) -> cv2.aruco.Dictionary:
        return cv2.aruco.getPredefinedDictionary(getattr(cv2.aruco, self.dictionary))

    def cv_board(self) -> cv2.aruco.CharucoBoard:
        """A new ``cv2.aruco.CharucoBoard`` (OpenCV objects are mutable, so never share one)."""
        board = cv2.aruco.CharucoBoard(
            (self.squares_x, self.squares_y), self.square_length_m, self.marker_length_m, self.aruco_dictionary()
        )
        board.setLegacyPattern(self.legacy_pattern)
        return board

    @property
    def size_m(self) -> tuple[float, float]:
        """Chessboard width and height in metres (without the margin)."""
        return self.squares_x * self.square_length_m, self.squares_y * self.square_length_m

    @property
    def page_size_m(self) -> tuple[float, float]:
        """Printed page width and height in metres: the board plus the margin on each side."""
        w, h = self.size_m
        return w + 2.0 * self.margin_m, h + 2.0 * self.margin_m

    @property
    def n_corners(self) -> int:
        return (self.squares_x - 1) * (self.squares_y - 1)

    def corner_points(self) -> FloatArray:
        """``(n_corners, 3)`` board-frame chessboard corners in metres, row ``k`` = corner id ``k`` (float64)."""
        k = np.arange(self.n_corners)
        nx = self.squares_x - 1
        pts = np.zeros((self.n_corners, 3))
        pts[:, 0] = (k % nx + 1) * self.square_length_m
        pts[:, 1] = (k // nx + 1) * self.square_length_m
        return pts

    @cached_property
    def _layout(self) -> tuple[Rect, ...]:
        s, m = self.square_length_m, self.marker_length_m
        board = self.cv_board()
        offset = (s - m) / 2.0
        dictionary = self.aruco_dictionary()
        cells = dictionary.markerSize + 2  # data bits plus the one-cell black border
        cell = m / cells
        rects: list[Rect] = []
        with_marker: set[tuple[int, int]] = set()
        for corners, marker_id in zip(board.getObjPoints(), np.asarray(board.getIds()).ravel(), strict=True):
            # OpenCV stores float32 corners; recover the square index and recompute them exactly.
            col = round((float(corners[0][0]) - offset) / s)
            row = round((float(corners[0][1]) - offset) / s)
            with_marker.add((col, row))
            bits = cv2.aruco.generateImageMarker(dictionary, int(marker_id), cells, borderBits=1) < 128
            x_m, y_m = col * s + offset, row * s + offset
            for r in range(cells):
                c = 0
                while c < cells:  # one rectangle per horizontal run of black cells: fewer seams in viewers
                    if not bits[r, c]:
                        c += 1
                        continue
                    start = c
                    while c < cells and bits[r, c]:
                        c += 1
                    rects.append((x_m + start * cell, y_m + r * cell, x_m + c * cell, y_m + (r + 1) * cell))
        # In a ChArUco board the markers sit in the white squares; every other square is black.
        for row in range(self.squares_y):
            for col in range(self.squares_x):
                if (col, row) not in with_marker:
                    rects.append((col * s, row * s, (col + 1) * s, (row + 1) * s))
        return tuple(rects)

    def black_rectangles(self) -> tuple[Rect, ...]:
        """The black areas of the printed board as rectangles ``(x0, y0, x1, y1)``, board frame, metres."""
        return self._layout

    # ------------------------------------------------------------------ rendering

    def render(self, pixels_per_metre: float, antialias: bool = False, margin_m: float | None = None) -> UInt8Array:
        """The board as a grayscale image (0 black, 255 white) including ``margin_m`` (default: the config's).

        Pixel ``(i, j)`` covers ``[j, j + 1) x [i, i + 1)`` / ``pixels_per_metre`` of the page, so the image is
        true to scale at that resolution. Without ``antialias`` a pixel is black if its centre is in a black
        rectangle (crisp output for printing); with it, its grey level is the exact covered area, which is
        what the synthetic camera needs to place edges with sub-pixel accuracy.
        """
        ppm = float(pixels_per_metre)
        if not (math.isfinite(ppm) and ppm > 0.0):
            raise ValueError(f"pixels_per_metre must be a positive number, got {pixels_per_metre!r}")
        margin = self.margin_m if margin_m is None else float(margin_m)
        if not (math.isfinite(margin) and margin >= 0.0):
            raise ValueError(f"margin_m must be a length >= 0 in metres, got {margin_m!r}")
        w_m, h_m = self.size_m
        width, height = round((w_m + 2 * margin) * ppm), round((h_m + 2 * margin) * ppm)
        if width * height > 20000 * 20000:
            raise ValueError(f"render: {width}x{height} pixels is too large; lower the resolution")
        black = np.zeros((height, width), dtype=np.float64)
        for x0, y0, x1, y1 in self._layout:
            u0, u1, v0, v1 = (x0 + margin) * ppm, (x1 + margin) * ppm, (y0 + margin) * ppm, (y1 + margin) * ppm
            if antialias:
                cols, cov_x = _coverage(u0, u1, width)
                rows, cov_y = _coverage(v0, v1, height)
                black[rows, cols] += cov_y[:, None] * cov_x[None, :]
            else:
                # Pixels whose centre j + 0.5 lies in [u0, u1): j from ceil(u0 - 0.5) to ceil(u1 - 0.5) - 1.
                r0, r1, c0, c1 = (math.ceil(e - 0.5) for e in (v0, v1, u0, u1))
                black[max(r0, 0) : max(r1, 0), max(c0, 0) : max(c1, 0)] = 1.0
        return np.asarray(np.round(255.0 * (1.0 - np.clip(black, 0.0, 1.0))), dtype=np.uint8)

    def write_png(self, path: str | Path, dpi: float = 300.0) -> tuple[int, int]:
        """Write a crisp PNG at ``dpi`` with its physical resolution recorded (pHYs); returns (width, height)."""
        if not (math.isfinite(dpi) and 10.0 <= dpi <= 2400.0):
            raise ValueError(f"dpi must be in 10..2400, got {dpi!r}")
        ppm = dpi / METRES_PER_INCH
        image = self.render(ppm)
        ok, encoded = cv2.imencode(".png", image)
        if not ok:
            raise OSError(f"could not encode the board PNG for {path}")
        Path(path).write_bytes(_with_phys_chunk(encoded.tobytes(), round(ppm)))
        return int(image.shape[1]), int(image.shape[0])

    def write_pdf(self, path: str | Path) -> tuple[float, float]:
        """Write a one-page vector PDF exactly :attr:`page_size_m` large; returns the page size in points."""
        caption = (
            f"{self.name}: ChArUco {self.squares_x}x{self.squares_y}, square {self.square_length_m * 1e3:.2f} mm, "
            f"marker {self.marker_length_m * 1e3:.2f} mm, {self.dictionary}"
            f"{', legacy pattern' if self.legacy_pattern else ''}. Print at 100 % (actual size); measure a square."
        )
        m = self.margin_m
        rects = [(x0 + m, y0 + m, x1 + m, y1 + m) for x0, y0, x1, y1 in self._layout]
        # The caption goes in the bottom margin when there is room for legible (>= 4 pt) text.
        font_pt = min(7.0, 0.45 * m / METRES_PER_INCH * 72.0)
        return write_rectangles_pdf(
            path,
            self.page_size_m,
            rects,
            caption=caption if font_pt >= 4.0 else None,
            caption_at_m=(m, self.page_size_m[1] - 0.35 * m),
            caption_pt=font_pt,
            title=f"ChArUco board {self.name}",
        )


def _coverage(a: float, b: float, n: int) -> tuple[slice, FloatArray]:
    """Pixels overlapping ``[a, b)`` (pixel j covers ``[j, j + 1)``) and the overlap length of each."""
    j0, j1 = max(math.floor(a), 0), min(math.ceil(b), n)
    if j1 <= j0:
        return slice(0, 0), np.zeros(0)
    j = np.arange(j0, j1, dtype=np.float64)
    return slice(j0, j1), np.clip(np.minimum(j + 1.0, b) - np.maximum(j, a), 0.0, 1.0)


def _with_phys_chunk(png: bytes, pixels_per_metre: int) -> bytes:
    """Insert a pHYs chunk (pixels per metre, unit = metre) after IHDR so viewers know the print size."""
    data = struct.pack(">IIB", pixels_per_metre, pixels_per_metre, 1)
    chunk = struct.pack(">I", len(data)) + b"pHYs" + data + struct.pack(">I", zlib.crc32(b"pHYs" + data))
    ihdr_end = 8 + 4 + 4 + 13 + 4  # signature, then IHDR's length, type, 13 data bytes and CRC
    return png[:ihdr_end] + chunk + png[ihdr_end:]
