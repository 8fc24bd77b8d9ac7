"""Γ⁺: the kinematic control video of a chunk in every view — the robot's own render, the paper's markers,
the scene reprojected into moving cameras — in the combination a style names.

``GammaPlus(rig, style)(chunk, current_images=…, current_state=…) -> ControlFrames``:

1. the chunk's K stride-aligned actions (rows Δ−1, 2Δ−1, …, KΔ−1), validated as Γ validates them; the
   render and the prior use them delayed by the rig's servo lag (``control_lag_steps``,
   :mod:`~pilworld.control_video.lag`), where the arm will actually be; the markers use them as they are;
2. ``render``: the robot at each of them in every camera (:mod:`~pilworld.control_video.robot_render`);
3. ``markers``: the paper's Γ in the head view (:class:`~pilworld.control_video.gamma.ControlVideo`,
   unchanged; the wrist views carry no markers, as in the paper);
4. ``prior``: each view's current frame warped into its future poses through the table plane
   (:mod:`~pilworld.control_video.reprojection`), the robot's own pixels removed — those of the current
   frame from a render of ``current_state``, those of each future frame from step 2.

``ControlFrames`` keeps every part separately (part ids, depth, shaded render, markers, prior and its
source map) for the world model to choose from, plus ``images``: one picture per view and frame — the
prior (black where it has nothing), the shaded robot over it, the markers over that — which is what
``pilworld control-video`` writes and docs/control_video.md shows.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass

import cv2
import numpy as np
from numpy.typing import NDArray

from pilworld.config.rig import RigConfig
from pilworld.control_video.cameras import RigCameras
from pilworld.control_video.gamma import ControlVideo
from pilworld.control_video.lag import lagged_poses
from pilworld.control_video.reprojection import ReprojectionPrior, SceneReprojector
from pilworld.control_video.robot_model import RobotModel
from pilworld.control_video.robot_render import Backend, RobotRender, RobotRendererBackend, make_robot_renderer
from pilworld.control_video.style import ControlVideoStyle
from pilworld.control_video.styles import Style
from pilworld.types import HEAD_VIEW, STATE_DIM, ActionChunk, ChunkSpec

U8 = NDArray[np.uint8]


@dataclass(frozen=True, eq=False)
class ControlFrames:
    """Γ⁺ of one chunk: K frames per view (every array has K on axis 0)."""

    style: str
    images: dict[str, U8]  # view → (K, H, W, 3): the style's picture (see the module docstring)
    render: RobotRender | None  # part ids, depth, shaded robot per view (render styles)
    markers: U8 | None  # (K, H, W, 3) head-view Γ (marker styles)
    prior: ReprojectionPrior | None  # warped current frames and their sources (prior styles)

    @property
    def views(self) -> tuple[str, ...]:
        return tuple(self.images)


class GammaPlus:
    """Γ⁺ for one rig and style; see the module docstring."""

    def __init__(
        self,
        rig: RigConfig,
        style: str | Style = "render",
        *,
        spec: ChunkSpec | None = None,
        backend: Backend = "analytic",
        robot: RobotModel | None = None,
        cameras: RigCameras | None = None,
        marker_style: ControlVideoStyle | None = None,
        lag_steps: float | None = None,
    ) -> None:
        self.style = style if isinstance(style, Style) else Style.parse(style)
        self.spec = spec or ChunkSpec()
        # The render and the prior place the robot where it will be (the commands delayed by the servo lag).
        self.lag_steps = rig.control_lag_steps if lag_steps is None else float(lag_steps)
        if not (np.isfinite(self.lag_steps) and 0.0 <= self.lag_steps <= self.spec.executed_steps):
            raise ValueError(f"lag_steps: expected control steps in [0, {self.spec.executed_steps}], got {lag_steps!r}")
        self.cameras = cameras or RigCameras.from_rig(rig)
        head = next((v for v in self.cameras.views if v.name == HEAD_VIEW), None)
        if self.style.markers and head is None:
            raise ValueError(f"style {self.style.name!r}: markers are drawn in {HEAD_VIEW!r}, not among the views")
        # Γ is drawn through the same head camera the renderer uses (a perturbed camera moves both).
        self.markers = ControlVideo(
            rig.kinematics, head.model if head is not None else rig.head_camera_model, self.spec, marker_style
        )
        self.renderer: RobotRendererBackend | None = None
        if self.style.render or self.style.prior:  # the prior needs the robot's pixels removed
            self.renderer = make_robot_renderer(rig, backend, robot=robot, cameras=self.cameras)
        self.reprojector = SceneReprojector(self.cameras) if self.style.prior else None

    @property
    def views(self) -> tuple[str, ...]:
        return self.cameras.names

    def __call__(
        self,
        chunk: NDArray[np.floating] | ActionChunk,
        *,
        previous_state: NDArray[np.floating] | None = None,
        current_images: Mapping[str, U8] | None = None,
        current_state: NDArray[np.floating] | None = None,
        current_robot_masks: Mapping[str, NDArray[np.bool_]] | None = None,
    ) -> ControlFrames:
        """Γ⁺ of one chunk (H_π, 14).

        ``previous_state`` (14,) adds the markers' trace into frame 0, as for Γ. The prior needs
        ``current_images`` (view → uint8 (H, W, 3)) and ``current_state`` (14,; defaults to
        ``previous_state``); ``current_robot_masks`` overrides the render of the current robot pixels.
        """
        stride = self.markers.stride_aligned(chunk)  # validates shape, length and finiteness
        if stride.ndim != 2:
            raise ValueError(f"actions: expected one chunk (H, {STATE_DIM}), got a batch of shape {stride.shape}")
        K = stride.shape[0]
        state = current_state if current_state is not None else previous_state
        if self.style.prior:
            if current_images is None or state is None:
                raise ValueError(
                    f"style {self.style.name!r}: the prior needs current_images and current_state (the frame and "
                    "joint state the chunk starts from)"
                )
            state_arr = np.asarray(state, dtype=np.float64)
            if state_arr.shape != (STATE_DIM,) or not np.all(np.isfinite(state_arr)):
                raise ValueError(f"current_state: expected {STATE_DIM} finite values, got shape {state_arr.shape}")

        render: RobotRender | None = None
        now_masks: dict[str, NDArray[np.bool_]] | None = None
        poses = stride
        if self.lag_steps > 0 and (self.renderer is not None or self.reprojector is not None):
            chunk_arr = np.asarray(chunk.actions if isinstance(chunk, ActionChunk) else chunk, dtype=np.float64)
            poses = lagged_poses(chunk_arr, state, self.spec, self.lag_steps)
        if self.renderer is not None:
            want_current = self.style.prior and current_robot_masks is None
            q = np.concatenate([np.asarray(state, dtype=np.float64)[None], poses]) if want_current else poses
            full = self.renderer.render(q, depth=self.style.render, shaded=self.style.render)
            if want_current:
                now_masks = {v: p[0] > 0 for v, p in full.parts.items()}
                render = RobotRender(
                    {v: p[1:] for v, p in full.parts.items()},
                    None if full.depth is None else {v: d[1:] for v, d in full.depth.items()},
                    None if full.shaded is None else {v: s[1:] for v, s in full.shaded.items()},
                )
            else:
                render = full
        markers = self.markers(chunk, previous_state) if self.style.markers else None
        prior = None
        if self.reprojector is not None:
            assert current_images is not None and state is not None and render is not None
            masks = now_masks if current_robot_masks is None else dict(current_robot_masks)
            prior = self.reprojector(current_images, np.asarray(state), poses, masks, render.mask)
        images = self._compose(K, render if self.style.render else None, markers, prior)
        return ControlFrames(self.style.name, images, render if self.style.render else None, markers, prior)

    def _compose(
        self, K: int, render: RobotRender | None, markers: U8 | None, prior: ReprojectionPrior | None
    ) -> dict[str, U8]:
        out: dict[str, U8] = {}
        for view in self.cameras.views:
            h, w = view.model.height, view.model.width
            img = prior.images[view.name].copy() if prior is not None else np.zeros((K, h, w, 3), dtype=np.uint8)
            # Each layer over the last where it draws (OpenCV's masked copy per frame: ~20× numpy's).
            if render is not None:
                assert render.shaded is not None
                _over(img, render.shaded[view.name], render.parts[view.name] > 0)
            if markers is not None and view.name == HEAD_VIEW:
                _over(img, markers, (markers[..., 0] | markers[..., 1] | markers[..., 2]) > 0)
            out[view.name] = img
        return out


def _over(dst: U8, layer: U8, where: NDArray[np.bool_]) -> None:
    """``dst[where] = layer[where]`` for (K, H, W, 3) frames, in place."""
    mask = where.view(np.uint8)
    for k in range(dst.shape[0]):
        cv2.copyTo(layer[k], mask[k], dst[k])
