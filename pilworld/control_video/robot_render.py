"""The robot rendered from its own model in every camera of the rig: part-id masks, depth, shaded images.

What a render holds is :class:`~pilworld.control_video.robot_frames.RobotRender` (re-exported here); this
module chooses the backend.

``RobotRenderer.from_rig(rig)(q14)`` renders joint vectors (N, 14) — typically the K stride-aligned
actions of a chunk — in every view: the head camera through its calibrated ``CameraModel``, each wrist
camera from its mount on the TCP (:mod:`pilworld.control_video.cameras`). The geometry is the robot the
simulated rig is built from (:mod:`pilworld.control_video.robot_model`). Two backends draw it:

* ``analytic`` (default): the robot's convex primitives projected exactly and filled by OpenCV
  (:mod:`pilworld.control_video.rasterise`); depth and shading by ray casting at the robot's pixels.
  Fast enough for every chunk of a rollout.
* ``mujoco``: MuJoCo's own renderer on the robot-only model (:mod:`pilworld.control_video.robot_render_mujoco`);
  the reference the analytic backend is tested against, and the way to render a user MJCF with meshes.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import TYPE_CHECKING, Literal, Protocol

import numpy as np
from numpy.typing import NDArray

from pilworld.control_video.robot_frames import RobotRender as RobotRender  # re-exported: the render type

if TYPE_CHECKING:  # MuJoCo loads with the robot model; the CLI imports this module for BACKENDS only
    from pilworld.config.rig import RigConfig
    from pilworld.control_video.cameras import RigCameras
    from pilworld.control_video.robot_model import RobotModel

Backend = Literal["analytic", "mujoco"]
BACKENDS: tuple[Backend, ...] = ("analytic", "mujoco")


class RobotRendererBackend(Protocol):
    """What a backend implements: render (N, 14) joint vectors in every view."""

    cameras: RigCameras
    robot: RobotModel

    def render(
        self,
        q14: NDArray[np.floating],
        *,
        depth: bool = True,
        shaded: bool = True,
        views: Sequence[str] | None = None,
    ) -> RobotRender: ...


def make_robot_renderer(
    rig: RigConfig,
    backend: Backend = "analytic",
    *,
    robot: RobotModel | None = None,
    cameras: RigCameras | None = None,
) -> RobotRendererBackend:
    """A renderer of ``rig``'s robot in all its cameras; ``robot``/``cameras`` override (stability probes)."""
    from pilworld.control_video.cameras import RigCameras
    from pilworld.control_video.robot_model import RobotModel

    robot = robot or RobotModel.from_rig(rig)
    cameras = cameras or RigCameras.from_rig(rig)
    if backend == "analytic":
        from pilworld.control_video.rasterise import AnalyticRobotRenderer  # OpenCV and ray casting on demand

        return AnalyticRobotRenderer(robot, cameras)
    if backend == "mujoco":
        from pilworld.control_video.robot_render_mujoco import MujocoRobotRenderer  # MuJoCo only when asked

        return MujocoRobotRenderer(robot, cameras)
    raise ValueError(f"backend: expected one of {', '.join(BACKENDS)}, got {backend!r}")
