"""The simulated rig's cameras at a calibration resolution: the true intrinsics a simulated calibration uses.

The simulator renders an undistorted pinhole with square pixels and the principal point at the image
centre, so the intrinsics at any width follow from the field of view: a render ``resolution`` pixels wide
has ``f`` scaled with the height (MuJoCo's ``fovy`` spans the image height). The head camera keeps its
pose (``T_cam_base``, rig frame); a wrist camera sits at its *designed* mount (``T_cam_base = T_cam_tcp``,
the ``wrist_cameras.<name>.file`` convention), see docs/calibration.md, "Measured on the simulated rig" and
"Wrist cameras (eye-in-hand)".
"""

from __future__ import annotations

import math

import numpy as np
import numpy.typing as npt

from calib.camera_model import CameraModel
from pilworld.config.rig import RigConfig
from pilworld.geometry import invert_transform

__all__ = ["sim_calibration_camera", "sim_wrist_camera", "wrist_arm"]

FloatArray = npt.NDArray[np.float64]


def _pinhole(resolution: int, height: int, f: float, T_cam_base: FloatArray, name: str) -> CameraModel:
    width = resolution
    K = np.array([[f, 0.0, (width - 1) / 2.0], [0.0, f, (height - 1) / 2.0], [0.0, 0.0, 1.0]])
    return CameraModel(K=K, dist=np.zeros(0), T_cam_base=T_cam_base, width=width, height=height, name=name)


def _check_resolution(resolution: int) -> None:
    if isinstance(resolution, bool) or not isinstance(resolution, int) or not 16 <= resolution <= 8192:
        raise ValueError(f"resolution: expected an image width in pixels, 16..8192, got {resolution!r}")


def sim_calibration_camera(rig: RigConfig, resolution: int) -> CameraModel:
    """The simulated head camera rendered ``resolution`` pixels wide with the same field of view (true intrinsics)."""
    _check_resolution(resolution)
    cam = rig.head_camera_model
    height = round(resolution * cam.height / cam.width)
    return _pinhole(resolution, height, float(cam.K[1, 1]) * height / cam.height, cam.T_cam_base, cam.name)


def wrist_arm(rig: RigConfig, camera: str) -> str:
    """The arm carrying wrist camera ``camera``; ``ValueError`` listing the rig's cameras otherwise."""
    if camera not in rig.wrist_cameras:
        raise ValueError(
            f"--camera: unknown camera {camera!r}; rig {rig.name!r} has cameras {', '.join(rig.cameras)} "
            f"(wrist cameras: {', '.join(rig.wrist_cameras) or 'none'})"
        )
    return rig.wrist_cameras[camera].arm


def sim_wrist_camera(rig: RigConfig, camera: str, resolution: int) -> CameraModel:
    """The *designed* wrist camera ``resolution`` pixels wide (true intrinsics; ``T_cam_base = T_cam_tcp``).

    A ``file:`` in the rig config is ignored: the simulator places the camera at its designed mount
    (``pose_in_tcp``, ``fovy_deg``).
    """
    _check_resolution(resolution)
    wrist_arm(rig, camera)
    cam = rig.wrist_cameras[camera]
    height = round(resolution * rig.image_size.height / rig.image_size.width)
    f = height / (2.0 * math.tan(math.radians(cam.fovy_deg) / 2.0))
    return _pinhole(resolution, height, f, invert_transform(cam.pose_in_tcp.matrix()), camera)
