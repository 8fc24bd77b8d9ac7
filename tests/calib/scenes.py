"""Ground truth shared by the calibration tests: a true camera, boards and cached synthetic detections."""

from __future__ import annotations

from functools import lru_cache
from pathlib import Path

import numpy as np

from calib.board import ChArUcoBoard
from calib.camera_model import CameraModel
from calib.detect import BoardDetector, Detection
from calib.synthetic import perturb_detection, synthetic_views

BOARDS = Path(__file__).resolve().parents[2] / "configs" / "board"
A4 = BOARDS / "charuco_7x5_a4.yaml"
A3 = BOARDS / "charuco_12x9_a3.yaml"

#: The "unknown" camera: a 640x480 webcam-like lens with radial and tangential distortion.
TRUE_K = np.array([[600.0, 0.0, 322.5], [0.0, 603.0, 237.8], [0.0, 0.0, 1.0]])
TRUE_DIST = np.array([-0.12, 0.08, 0.0008, -0.0005, -0.02])
TRUE_CAMERA = CameraModel(K=TRUE_K, dist=TRUE_DIST, T_cam_base=np.eye(4), width=640, height=480)
TRUTH = {
    "fx": 600.0,
    "fy": 603.0,
    "cx": 322.5,
    "cy": 237.8,
    **{k: float(v) for k, v in zip(("k1", "k2", "p1", "p2", "k3"), TRUE_DIST, strict=True)},
}
NOISE_PX = 0.3  # per corner coordinate


@lru_cache(maxsize=32)
def noisy_detections(seed: int, n_views: int = 20, board_path: Path = A3) -> tuple[Detection, ...]:
    """``n_views`` rendered views (seed ``seed``), detected, with ``NOISE_PX`` Gaussian corner noise added."""
    board = ChArUcoBoard.from_yaml(board_path)
    views = synthetic_views(board, TRUE_CAMERA, n_views, seed=seed)
    detector = BoardDetector(board)
    rng = np.random.default_rng(10_000 + seed)
    return tuple(
        perturb_detection(detector.detect(v.image, f"view_{i:02d}.png"), NOISE_PX, rng) for i, v in enumerate(views)
    )
