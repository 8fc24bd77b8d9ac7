"""Camera calibration and the head-camera projection model shared by the control video and the simulator."""

from calib.camera_model import FORMAT, NEAR_Z, CameraModel, Projection
from calib.distortion import (
    VALID_COEFFICIENT_COUNTS,
    DistortionModel,
    distort_normalized,
    max_monotonic_radius,
    undistort_normalized,
)

__all__ = [
    "FORMAT",
    "NEAR_Z",
    "VALID_COEFFICIENT_COUNTS",
    "CameraModel",
    "DistortionModel",
    "Projection",
    "distort_normalized",
    "max_monotonic_radius",
    "undistort_normalized",
]
