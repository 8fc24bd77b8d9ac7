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


HAND_EYE_FUNCTIONS = ("calibrateHandEye", "calibrateRobotWorldHandEye")


def require_hand_eye() -> None:
    """Fail (never skip) when this cv2 lacks the hand-eye reference functions.

    The OpenCV cross-checks are how the tests know our solvers agree with an independent implementation;
    a cv2 without them (the 5.0.x Python wheels) must not turn those checks into silent skips.
    pyproject.toml excludes 5.0.* so a fresh install never resolves one.
    """
    missing = [f for f in HAND_EYE_FUNCTIONS if not hasattr(cv2, f)]
    if missing:
        raise AssertionError(
            f"OpenCV {cv2.__version__} has no cv2.{', cv2.'.join(missing)}: the hand-eye reference is missing; "
            "install opencv-contrib-python-headless>=4.10,!=5.0.*,<6 (as pyproject.toml pins it)"
        )
