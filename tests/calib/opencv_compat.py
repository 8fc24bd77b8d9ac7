"""OpenCV reference calls that moved between 4.x and 5.x (tests compare our maths against them)."""

from __future__ import annotations

from typing import Any

import cv2
import numpy as np


def undistort_points_iter(points: Any, K: Any, dist: Any, criteria: tuple[int, int, float]) -> Any:
    """``cv2.undistortPointsIter`` (4.x); 5.x dropped it and ``undistortPoints`` takes the criteria instead."""
    if hasattr(cv2, "undistortPointsIter"):
        return cv2.undistortPointsIter(points, K, dist, np.eye(3), np.eye(3), criteria)
    return cv2.undistortPoints(points, K, dist, R=np.eye(3), P=np.eye(3), criteria=criteria)
