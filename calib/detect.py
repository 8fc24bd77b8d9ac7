"""ChArUco corner detection that survives the OpenCV 4.6 legacy-pattern change.

OpenCV 4.6 changed where the markers of a ChArUco board with an even number of rows go
(``CharucoBoard.setLegacyPattern``, a known OpenCV upstream bug). A detector configured with the other layout
still finds every marker but interpolates **zero** corners, which looks like "the board is not visible".
:class:`BoardDetector` notices exactly that situation (markers found, no corners), retries with the
other layout, and if that works warns once with :class:`LegacyPatternMismatchWarning` (naming the config
change that fixes it) and keeps using the working layout for the following images.
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass, field

import cv2
import numpy as np
import numpy.typing as npt

from calib.board import ChArUcoBoard

__all__ = ["BoardDetector", "Detection", "LegacyPatternMismatchWarning"]

FloatArray = npt.NDArray[np.float64]
IntArray = npt.NDArray[np.int64]


class LegacyPatternMismatchWarning(UserWarning):
    """The images show the other ChArUco layout than the board config says; the detector switched."""


@dataclass(frozen=True, eq=False)
class Detection:
    """The ChArUco corners found in one image."""

    name: str  #: image identifier (usually the file name), used in reports
    image_size: tuple[int, int]  #: (width, height) in pixels
    corner_ids: IntArray  #: ``(N,)`` chessboard corner ids (row-major from the board's top-left)
    corners: FloatArray  #: ``(N, 2)`` float64 pixels (OpenCV convention: integers are pixel centres)
    marker_ids: IntArray  #: ``(M,)`` ids of the ArUco markers found
    legacy_pattern: bool  #: the layout the corners were interpolated with
    board: ChArUcoBoard = field(repr=False)  #: the board (with that layout)

    @property
    def n_corners(self) -> int:
        return int(self.corner_ids.shape[0])

    def object_image_points(self) -> tuple[FloatArray, FloatArray]:
        """``(N, 3)`` board-frame points (metres) and ``(N, 2)`` pixels, via ``CharucoBoard.matchImagePoints``."""
        if self.n_corners == 0:
            return np.zeros((0, 3)), np.zeros((0, 2))
        obj, img = self.board.cv_board().matchImagePoints(
            list(self.corners.reshape(-1, 1, 2).astype(np.float32)), self.corner_ids.reshape(-1, 1).astype(np.int32)
        )
        return np.asarray(obj, np.float64).reshape(-1, 3), np.asarray(img, np.float64).reshape(-1, 2)

    def with_corners(self, corners: npt.ArrayLike) -> Detection:
        """The same detection with other pixel positions for the same corner ids (e.g. with added noise)."""
        new = np.asarray(corners, dtype=np.float64).reshape(self.corners.shape)
        return Detection(
            self.name, self.image_size, self.corner_ids, new, self.marker_ids, self.legacy_pattern, self.board
        )


class BoardDetector:
    """Detect the ChArUco corners of ``board`` in images, correcting a legacy-pattern mismatch.

    ``min_markers`` is how many markers must be seen before "no corners" is blamed on the layout rather
    than on the view (one stray marker is not evidence of a board).
    """

    def __init__(self, board: ChArUcoBoard, min_markers: int = 2) -> None:
        self.board = board
        self.min_markers = int(min_markers)
        self._legacy = board.legacy_pattern
        self._detectors: dict[bool, cv2.aruco.CharucoDetector] = {}
        self._warned = False

    @property
    def legacy_pattern(self) -> bool:
        """The layout currently in use (differs from the config after a detected mismatch)."""
        return self._legacy

    def _detector(self, legacy: bool) -> cv2.aruco.CharucoDetector:
        if legacy not in self._detectors:
            self._detectors[legacy] = cv2.aruco.CharucoDetector(self.board.with_legacy_pattern(legacy).cv_board())
        return self._detectors[legacy]

    def _run(self, gray: npt.NDArray[np.uint8], legacy: bool) -> tuple[IntArray, FloatArray, IntArray]:
        corners, ids, _, marker_ids = self._detector(legacy).detectBoard(gray)
        c_ids = np.zeros(0, np.int64) if ids is None else np.asarray(ids, np.int64).reshape(-1)
        pts = np.zeros((0, 2)) if corners is None else np.asarray(corners, np.float64).reshape(-1, 2)
        m_ids = np.zeros(0, np.int64) if marker_ids is None else np.asarray(marker_ids, np.int64).reshape(-1)
        return c_ids, pts, m_ids

    def detect(self, image: npt.NDArray[np.uint8], name: str = "") -> Detection:
        """Corners in ``image`` (``(H, W)`` gray or ``(H, W, 3)`` BGR, uint8); an empty detection if none."""
        img = np.asarray(image)
        if img.dtype != np.uint8 or img.ndim not in (2, 3) or (img.ndim == 3 and img.shape[2] not in (1, 3, 4)):
            raise ValueError(
                f"image {name!r}: expected uint8 (H, W) gray or (H, W, 3) BGR, got {img.dtype} {img.shape}"
            )
        if img.ndim == 3 and img.shape[2] != 1:
            code = cv2.COLOR_BGRA2GRAY if img.shape[2] == 4 else cv2.COLOR_BGR2GRAY
            img = np.asarray(cv2.cvtColor(img, code), dtype=np.uint8)
        gray: npt.NDArray[np.uint8] = np.ascontiguousarray(img.reshape(img.shape[0], img.shape[1]))
        legacy = self._legacy
        c_ids, pts, m_ids = self._run(gray, legacy)
        if c_ids.size == 0 and m_ids.size >= self.min_markers:
            o_ids, o_pts, o_markers = self._run(gray, not legacy)
            if o_ids.size > 0:
                legacy, c_ids, pts, m_ids = not legacy, o_ids, o_pts, o_markers
                self._legacy = legacy
                self._warn(legacy, name)
        height, width = gray.shape[:2]
        order = np.argsort(c_ids, kind="stable")
        return Detection(
            name=name,
            image_size=(int(width), int(height)),
            corner_ids=c_ids[order],
            corners=pts[order],
            marker_ids=np.sort(m_ids),
            legacy_pattern=legacy,
            board=self.board.with_legacy_pattern(legacy),
        )

    def _warn(self, legacy: bool, name: str) -> None:
        if self._warned or legacy == self.board.legacy_pattern:
            return
        self._warned = True
        warnings.warn(
            f"ChArUco board {self.board.name!r}: image {name!r} shows markers but no corners with "
            f"legacy_pattern={str(self.board.legacy_pattern).lower()}; with legacy_pattern={str(legacy).lower()} "
            f"the corners are found, so that layout is used from now on. The board was printed with the "
            f"{'pre' if legacy else 'post'}-OpenCV-4.6 layout (boards with an even number of rows changed). "
            f"Fix: set 'legacy_pattern: {str(legacy).lower()}' in the board config (or reprint the board).",
            LegacyPatternMismatchWarning,
            stacklevel=3,
        )
