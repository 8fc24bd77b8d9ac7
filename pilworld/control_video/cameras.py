"""Every camera of a rig at any joint configuration: the head camera fixed, wrist cameras on their TCPs.

The head camera's pose is the calibrated ``T_cam_base`` (rig frame → camera). A wrist camera rides on
its arm: ``T_cam_rig(q) = T_cam_tcp · T_tcp_rig(q)``, with ``T_cam_tcp`` from the rig's wrist-camera
calibration file or its designed mount (:meth:`pilworld.config.rig.RigConfig.wrist_camera_model`), and
``T_rig_tcp(q)`` by the same forward kinematics the simulator, Γ and the calibration check use.

The robot renderer (:mod:`pilworld.control_video.robot_render`) and the scene reprojection prior
(:mod:`pilworld.control_video.reprojection`) both go through :class:`RigCameras`, so they agree on
where every camera is.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from calib.camera_model import CameraModel
from pilworld.config.rig import RigConfig
from pilworld.geometry import as_finite_array, invert_transform
from pilworld.kinematics.dual_arm import DualArmKinematics
from pilworld.types import ARM_SIDES, HEAD_VIEW, STATE_DIM


@dataclass(frozen=True, eq=False)
class ViewCamera:
    """One camera of the rig: its model (intrinsics at the rig's image size) and where it is mounted.

    ``arm`` is None for the head camera (then ``model.T_cam_base`` maps rig-frame points into the
    camera); for a wrist camera it is ``"left"`` or ``"right"`` and ``model.T_cam_base`` is ``T_cam_tcp``.
    """

    name: str
    model: CameraModel
    arm: str | None

    @property
    def moves(self) -> bool:
        return self.arm is not None


@dataclass(frozen=True, eq=False)
class RigCameras:
    """The rig's cameras (head first) and their poses for 14-d joint vectors."""

    kinematics: DualArmKinematics
    views: tuple[ViewCamera, ...]

    @classmethod
    def from_rig(cls, rig: RigConfig, views: tuple[str, ...] | None = None) -> RigCameras:
        """All cameras of ``rig`` (or the named ``views``, in that order) at ``rig.image_size``."""
        names = rig.cameras if views is None else tuple(views)
        unknown = [v for v in names if v not in rig.cameras]
        if unknown:
            raise ValueError(f"views: rig {rig.name!r} has no camera {unknown} (cameras: {list(rig.cameras)})")
        out = []
        for name in names:
            if name == HEAD_VIEW:
                out.append(ViewCamera(name, rig.head_camera_model, None))
            else:
                out.append(ViewCamera(name, rig.wrist_camera_model(name), rig.wrist_cameras[name].arm))
        return cls(rig.kinematics, tuple(out))

    @property
    def names(self) -> tuple[str, ...]:
        return tuple(v.name for v in self.views)

    def view(self, name: str) -> ViewCamera:
        for v in self.views:
            if v.name == name:
                return v
        raise ValueError(f"view {name!r}: the cameras are {list(self.names)}")

    def poses(self, q14: NDArray[np.floating]) -> dict[str, NDArray[np.float64]]:
        """``T_cam_rig`` (..., 4, 4) of every view for joint vectors (..., 14): rig-frame points → camera."""
        q = as_finite_array(q14, "q14", (STATE_DIM,))
        tcp = self.kinematics.tcp_poses(q)  # (..., 2, 4, 4) T_rig_tcp
        T_tcp_rig = {side: invert_transform(tcp[..., i, :, :]) for i, side in enumerate(ARM_SIDES)}
        out: dict[str, NDArray[np.float64]] = {}
        for v in self.views:
            if v.arm is None:
                out[v.name] = np.broadcast_to(v.model.T_cam_base, (*q.shape[:-1], 4, 4)).copy()
            else:
                out[v.name] = v.model.T_cam_base @ T_tcp_rig[v.arm]
        return out

    def models_at(self, q14: NDArray[np.floating]) -> dict[str, CameraModel]:
        """Each view's :class:`CameraModel` posed in the rig frame for one joint vector (14,)."""
        q = np.asarray(q14, dtype=np.float64)
        if q.shape != (STATE_DIM,):
            raise ValueError(f"q14: expected one {STATE_DIM}-d joint vector, got shape {q.shape}")
        poses = self.poses(q)
        return {v.name: v.model.with_pose(poses[v.name]) for v in self.views}
