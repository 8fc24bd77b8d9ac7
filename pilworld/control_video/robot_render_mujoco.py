"""The ``mujoco`` robot-render backend: MuJoCo's own renderer on the robot-only model.

For each joint vector the robot model's qpos is set (:meth:`RobotModel.qpos`, no physics) and
``mj_kinematics`` places the geoms; each view is then drawn through the exact camera of
:class:`~pilworld.control_video.cameras.RigCameras`, not through a camera of the model: after
``mjv_updateScene`` the scene's OpenGL camera is overwritten with the view's pose (OpenCV axes → OpenGL
axes: forward = +z, up = −y) and an off-axis frustum built from its ``K``. So any undistorted pinhole is
reproduced — non-square pixels and an off-centre principal point included — and a robot model without
cameras (a user's MJCF) renders as well as the generated one. Lens distortion cannot be drawn by a
rasteriser: such a camera is refused at construction with a ``ValueError``.

Three renders per view: segmentation (geom ids → part ids through ``robot.geom_ids``/``geom_part``),
depth (MuJoCo linearises the depth buffer to the distance along the optical axis, i.e. camera-frame Z,
the same quantity as :class:`RobotRender.depth`) and, if asked, the shaded RGB image (headlight on black).
Geoms in :data:`~pilworld.control_video.robot_model.HIDDEN_GROUP` (table, floor, objects) are hidden.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np
from numpy.typing import NDArray

from pilworld.control_video.cameras import RigCameras, ViewCamera
from pilworld.control_video.robot_frames import RobotRender
from pilworld.control_video.robot_model import HIDDEN_GROUP, RobotModel
from pilworld.geometry import as_finite_array
from pilworld.types import STATE_DIM
from simrig.gl import make_renderer, mujoco

__all__ = ["MujocoRobotRenderer", "check_renderable"]


def check_renderable(view: ViewCamera) -> None:
    """Raise ``ValueError`` for a camera MuJoCo's pinhole rasteriser cannot reproduce (lens distortion)."""
    cam = view.model
    if cam.dist.size and np.any(cam.dist != 0):
        raise ValueError(
            f"camera {view.name!r}: the mujoco robot renderer draws undistorted pinhole cameras only, got distortion "
            f"{np.asarray(cam.dist).tolist()}; use backend='analytic' (it projects through the CameraModel)"
        )
    K = np.asarray(cam.K, dtype=np.float64)
    if abs(K[0, 1]) > 1e-9 * K[0, 0]:
        raise ValueError(f"camera {view.name!r}: the mujoco robot renderer needs zero skew, got K[0,1]={K[0, 1]!r}")


def _frustum(view: ViewCamera, near: float) -> tuple[float, float, float, float]:
    """(center, half width, bottom, top) of the near plane for an OpenCV pinhole (pixel centres at integers)."""
    cam = view.model
    fx, fy, cx, cy = cam.K[0, 0], cam.K[1, 1], cam.K[0, 2], cam.K[1, 2]
    left = near * (-0.5 - cx) / fx
    right = near * (cam.width - 0.5 - cx) / fx
    top = near * (cy + 0.5) / fy  # image row −0.5 (OpenCV y down) is OpenGL's top
    bottom = near * (cy + 0.5 - cam.height) / fy
    return float((left + right) / 2), float((right - left) / 2), float(bottom), float(top)


class MujocoRobotRenderer:
    """Render (N, 14) joint vectors of ``robot`` in every view of ``cameras`` with MuJoCo (EGL/OSMesa)."""

    def __init__(self, robot: RobotModel, cameras: RigCameras) -> None:
        for view in cameras.views:
            check_renderable(view)
        self.robot = robot
        self.cameras = cameras
        m = robot.model
        self._data = mujoco.MjData(m)
        self._option = mujoco.MjvOption()
        self._option.geomgroup[HIDDEN_GROUP] = 0
        self._free = mujoco.MjvCamera()
        mujoco.mjv_defaultFreeCamera(m, self._free)
        # geom id → part id; index −1 (background, or a non-geom object) → 0.
        self._part_lut = np.zeros(m.ngeom + 1, dtype=np.uint8)
        self._part_lut[robot.geom_ids] = robot.geom_part
        vis = m.vis.global_  # the offscreen buffer must hold the largest view
        vis.offwidth = max(int(vis.offwidth), *(v.model.width for v in cameras.views))
        vis.offheight = max(int(vis.offheight), *(v.model.height for v in cameras.views))
        self._renderers: dict[tuple[int, int], Any] = {}
        for v in cameras.views:
            size = (v.model.width, v.model.height)
            if size not in self._renderers:
                self._renderers[size] = make_renderer(m, *size)

    def close(self) -> None:
        for r in self._renderers.values():
            r.close()
        self._renderers = {}

    def __enter__(self) -> MujocoRobotRenderer:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def _place_camera(self, renderer: Any, view: ViewCamera, T_cam_rig: NDArray[np.float64]) -> None:
        """Overwrite the scene's camera (and headlight) with the view's exact pose and intrinsics."""
        scene = renderer.scene
        R, t = T_cam_rig[:3, :3], T_cam_rig[:3, 3]
        pos = -R.T @ t
        forward, up = R[2], -R[1]  # the camera's +z and −y axes in the rig frame
        for i in range(2):  # both eyes (mjv_averageCamera averages them)
            gl = scene.camera[i]
            gl.pos[:] = pos
            gl.forward[:] = forward
            gl.up[:] = up
            gl.orthographic = 0
            center, width, bottom, top = _frustum(view, float(gl.frustum_near))
            gl.frustum_center, gl.frustum_width = center, width
            gl.frustum_bottom, gl.frustum_top = bottom, top
        if scene.nlight > 0 and scene.lights[0].headlight:
            scene.lights[0].pos[:] = pos
            scene.lights[0].dir[:] = forward

    def render(
        self,
        q14: NDArray[np.floating],
        *,
        depth: bool = True,
        shaded: bool = True,
        views: Sequence[str] | None = None,
    ) -> RobotRender:
        """Part ids, depth and shaded images of joint vectors (N, 14) (or one (14,)) in every view (or in ``views``)."""
        q = as_finite_array(q14, "q14", (STATE_DIM,)).reshape(-1, STATE_DIM)
        qpos = self.robot.qpos(q)
        poses = self.cameras.poses(q)  # view → (N, 4, 4)
        m, d = self.robot.model, self._data
        n = q.shape[0]
        parts: dict[str, NDArray[np.uint8]] = {}
        depths: dict[str, NDArray[np.float32]] = {}
        images: dict[str, NDArray[np.uint8]] = {}
        chosen = [v for v in self.cameras.views if views is None or v.name in views]
        for v in chosen:
            h, w = v.model.height, v.model.width
            parts[v.name] = np.zeros((n, h, w), dtype=np.uint8)
            if depth:
                depths[v.name] = np.zeros((n, h, w), dtype=np.float32)
            if shaded:
                images[v.name] = np.zeros((n, h, w, 3), dtype=np.uint8)
        for i in range(n):
            d.qpos[:] = qpos[i]
            mujoco.mj_kinematics(m, d)
            for v in chosen:
                r = self._renderers[(v.model.width, v.model.height)]
                r.update_scene(d, camera=self._free, scene_option=self._option)
                self._place_camera(r, v, poses[v.name][i])
                r.enable_segmentation_rendering()
                seg = r.render()
                r.disable_segmentation_rendering()
                ids = np.where(seg[..., 1] == int(mujoco.mjtObj.mjOBJ_GEOM), seg[..., 0], -1)
                p = self._part_lut[ids]
                parts[v.name][i] = p
                if depth:
                    r.enable_depth_rendering()
                    z = r.render()
                    r.disable_depth_rendering()
                    depths[v.name][i] = np.where(p > 0, z, 0.0)
                if shaded:
                    images[v.name][i] = np.where(p[..., None] > 0, r.render(), 0)
        return RobotRender(parts=parts, depth=depths if depth else None, shaded=images if shaded else None)
