"""Tests for calib.synthetic: rendered views agree with the true projection."""

from __future__ import annotations

import numpy as np
import pytest

from calib.board import ChArUcoBoard
from calib.detect import BoardDetector
from calib.synthetic import perturb_detection, synthetic_views

from .scenes import A4, TRUE_CAMERA


def test_detected_corners_match_the_true_projection() -> None:
    board = ChArUcoBoard.from_yaml(A4)
    views = synthetic_views(board, TRUE_CAMERA, 6, seed=3)
    detector = BoardDetector(board)
    errors = []
    for view in views:
        det = detector.detect(view.image)
        assert det.n_corners >= 12  # at 60° tilt a few far markers may be missed
        errors.append(det.corners - view.corners_true[det.corner_ids])
        # Every outer corner is inside the image (the generator's promise).
        assert np.all(view.corners_true >= 0) and np.all(view.corners_true[:, 0] < TRUE_CAMERA.width)
    err = np.concatenate(errors)
    # Rendering and detection agree to a small fraction of the 0.3 px calibration noise, without bias.
    assert np.sqrt((err**2).mean()) < 0.1
    assert np.abs(err.mean(axis=0)).max() < 0.02


def test_seeded_and_varied() -> None:
    board = ChArUcoBoard.from_yaml(A4)
    a = synthetic_views(board, TRUE_CAMERA, 2, seed=5)
    b = synthetic_views(board, TRUE_CAMERA, 2, seed=5)
    c = synthetic_views(board, TRUE_CAMERA, 2, seed=6)
    assert np.array_equal(a[0].image, b[0].image) and np.array_equal(a[1].T_cam_board, b[1].T_cam_board)
    assert not np.allclose(a[0].T_cam_board, c[0].T_cam_board)
    assert not np.allclose(a[0].T_cam_board, a[1].T_cam_board)


def test_perturb_detection_noise_level() -> None:
    board = ChArUcoBoard.from_yaml(A4)
    det = BoardDetector(board).detect(synthetic_views(board, TRUE_CAMERA, 1, seed=0)[0].image)
    rng = np.random.default_rng(0)
    diffs = np.concatenate([perturb_detection(det, 0.3, rng).corners - det.corners for _ in range(200)])
    assert np.std(diffs) == pytest.approx(0.3, rel=0.05)
    with pytest.raises(ValueError, match="sigma_px"):
        perturb_detection(det, -1.0, rng)
