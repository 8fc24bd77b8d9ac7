"""Tests for calib.detect: detection and the legacy-pattern mismatch."""

from __future__ import annotations

import warnings

import cv2
import numpy as np
import pytest

from calib.board import ChArUcoBoard
from calib.detect import BoardDetector, LegacyPatternMismatchWarning


def _board(legacy: bool, rows: int = 6) -> ChArUcoBoard:
    return ChArUcoBoard(8, rows, 0.03, 0.022, "DICT_5X5_100", legacy_pattern=legacy, name="even")


def _image(board: ChArUcoBoard) -> np.ndarray:
    return board.render(2500.0, margin_m=0.015)


@pytest.mark.parametrize("printed_legacy", [False, True])
def test_mismatch_is_detected_corrected_and_warned_once(printed_legacy: bool) -> None:
    printed = _board(printed_legacy)
    configured = _board(not printed_legacy)
    image = _image(printed)
    # The failure this guards against: plain OpenCV finds every marker but no corner.
    _, ids, _, markers = cv2.aruco.CharucoDetector(configured.cv_board()).detectBoard(image)
    assert markers is not None and len(markers) == 24 and (ids is None or len(ids) == 0)

    detector = BoardDetector(configured)
    with pytest.warns(LegacyPatternMismatchWarning, match=f"legacy_pattern: {str(printed_legacy).lower()}") as rec:
        det = detector.detect(image, "img0.png")
    assert "img0.png" in str(rec[0].message) and "'even'" in str(rec[0].message)
    assert det.n_corners == printed.n_corners and det.legacy_pattern == printed_legacy
    assert detector.legacy_pattern == printed_legacy
    # Object points follow the layout that worked.
    obj, img = det.object_image_points()
    np.testing.assert_allclose(obj, printed.corner_points()[det.corner_ids], atol=1e-7)
    np.testing.assert_allclose(img, det.corners, atol=1e-4)
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # the switch sticks: no second warning, no second detection pass
        assert detector.detect(image, "img1.png").n_corners == printed.n_corners


def test_matching_and_odd_row_boards_do_not_warn() -> None:
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        for legacy in (False, True):
            assert BoardDetector(_board(legacy)).detect(_image(_board(legacy))).n_corners == 35
            # With an odd number of rows both layouts are the same board.
            odd = _board(legacy, rows=5)
            assert BoardDetector(_board(not legacy, rows=5)).detect(_image(odd)).n_corners == 28


def test_corner_positions_and_colour_input() -> None:
    board = _board(False)
    ppm, margin = 2500.0, 0.015
    # Antialiased: here every corner falls on a pixel centre, which a binary render would shift by 0.5 px.
    image = board.render(ppm, antialias=True, margin_m=margin)
    det = BoardDetector(board).detect(cv2.cvtColor(image, cv2.COLOR_GRAY2BGR), "colour")
    assert det.image_size == (image.shape[1], image.shape[0])
    np.testing.assert_array_equal(det.corner_ids, np.arange(35))
    expected = (board.corner_points()[:, :2] + margin) * ppm - 0.5  # pixel centres are integers
    assert np.abs(det.corners - expected).max() < 0.05


def test_no_board_and_bad_input() -> None:
    detector = BoardDetector(_board(False))
    empty = detector.detect(np.full((120, 160), 200, np.uint8), "blank")
    assert empty.n_corners == 0 and empty.corners.shape == (0, 2)
    with pytest.raises(ValueError, match="expected uint8"):
        detector.detect(np.zeros((10, 10), np.float32), "float")
