"""Γ, the action-to-control projection (paper §3.2, appendix "Control-Video Projection Details").

An action chunk (H_π × 14) becomes K head-view control frames:

1. the K stride-aligned actions ``a_{t+Δ}, …, a_{t+KΔ}`` (rows Δ−1, 2Δ−1, …, KΔ−1);
2. left and right TCP positions in the rig frame by forward kinematics;
3. projection into the head camera (intrinsics, OpenCV distortion, ``T_cam_base``);
4. one marker per gripper (distinct colour per arm, radius encoding the opening, see
   :mod:`pilworld.control_video.style`) and short fading traces between consecutive positions.

Geometry (FK, projection, clipping) is vectorised over frames, arms and chunks; drawing uses OpenCV's
anti-aliased primitives at 1/16-pixel precision, so a marker's centre lands on its projected point to
well under half a pixel. Output is a pure function of the inputs: two renders are byte-identical.

Points the camera cannot show are handled, never raised:

* behind the camera (or closer than the camera model's near limit), or outside the range where the
  lens model is monotonic: no marker, and no trace segment touching that point;
* in front but off the image: the marker is drawn if its disc still overlaps the image (a gripper at
  the border stays partly visible, as it would in the camera), otherwise it is skipped; trace segments
  are clipped to the image, so a gripper leaving the view leaves a trace pointing where it went.
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np
from numpy.typing import NDArray

from calib.camera_model import CameraModel
from pilworld.config.rig import RigConfig
from pilworld.control_video.style import ControlVideoStyle
from pilworld.kinematics.dual_arm import DualArmKinematics
from pilworld.types import STATE_DIM, ActionChunk, ChunkSpec

_SHIFT = 4  # OpenCV drawing with 4 fractional bits: coordinates in 1/16 px
_ONE = 1 << _SHIFT


@dataclass(frozen=True, eq=False)
class ControlGeometry:
    """Where Γ draws, for a batch of chunks (leading shape ``B``), K frames and 2 arms.

    ``uv`` has the extended sequence on axis 1: with a previous state, index 0 is that state and
    index k + 1 is frame k; without it, index k is frame k (``offset`` tells which).
    """

    uv: NDArray[np.float64]  # (B, N, 2, 2) projected TCP pixels, N = K + offset
    usable: NDArray[np.bool_]  # (B, N, 2) in front of the camera and inside the lens model's range
    visible: NDArray[np.bool_]  # (B, N, 2) usable and the centre inside the image
    radius: NDArray[np.float64]  # (B, K, 2) marker radius in pixels
    marker: NDArray[np.bool_]  # (B, K, 2) marker drawn: usable and its disc overlaps the image
    seg_a: NDArray[np.float64]  # (B, N, 2, 2) clipped start of the segment ending at index i
    seg_b: NDArray[np.float64]  # (B, N, 2, 2) clipped end of that segment
    seg_ok: NDArray[np.bool_]  # (B, N, 2) segment ending at index i exists and crosses the image
    offset: int  # 1 when a previous state was given, else 0

    @property
    def frame_uv(self) -> NDArray[np.float64]:
        """(B, K, 2, 2) projected positions of the K frames (previous state removed)."""
        return self.uv[:, self.offset :]


def clip_segments(
    a: NDArray[np.float64], b: NDArray[np.float64], lo: tuple[float, float], hi: tuple[float, float]
) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.bool_]]:
    """Liang–Barsky clipping of segments a→b (..., 2) to the box [lo, hi]; returns (a', b', crosses)."""
    d = b - a
    t0 = np.zeros(a.shape[:-1])
    t1 = np.ones(a.shape[:-1])
    ok = np.ones(a.shape[:-1], dtype=bool)
    with np.errstate(divide="ignore", invalid="ignore"):
        for axis in (0, 1):
            for p, q in ((-d[..., axis], a[..., axis] - lo[axis]), (d[..., axis], hi[axis] - a[..., axis])):
                parallel = p == 0
                ok &= ~(parallel & (q < 0))
                r = q / np.where(parallel, 1.0, p)
                t0 = np.where(~parallel & (p < 0), np.maximum(t0, r), t0)
                t1 = np.where(~parallel & (p > 0), np.minimum(t1, r), t1)
    ok &= t0 <= t1
    return a + t0[..., None] * d, a + t1[..., None] * d, ok


class ControlVideo:
    """Γ for one rig: ``ControlVideo(...)(chunk) -> uint8[K, H, W, 3]`` (RGB, black background)."""

    def __init__(
        self,
        kinematics: DualArmKinematics,
        camera: CameraModel,
        spec: ChunkSpec | None = None,
        style: ControlVideoStyle | None = None,
    ) -> None:
        self.kinematics = kinematics
        self.camera = camera
        self.spec = spec or ChunkSpec()
        self.style = style or ControlVideoStyle()
        self.width, self.height = camera.width, camera.height
        self._fade_colors = [
            [tuple(float(c) * f for c in color) for f in self.style.trace_fade()] for color in self.style.colors
        ]
        self._thickness = self.style.trace_thickness(self.width, self.height)
        self._line_type = cv2.LINE_AA if self.style.antialias else cv2.LINE_8
        self._aa_pad = 0.5 if self.style.antialias else 0.0

    @classmethod
    def from_rig(
        cls, rig: RigConfig, spec: ChunkSpec | None = None, style: ControlVideoStyle | None = None
    ) -> ControlVideo:
        return cls(rig.kinematics, rig.head_camera_model, spec, style)

    # ------------------------------------------------------------------ geometry (vectorised)

    def _as_chunks(self, chunks: NDArray[np.floating] | ActionChunk, name: str) -> NDArray[np.float64]:
        arr = np.asarray(chunks.actions if isinstance(chunks, ActionChunk) else chunks, dtype=np.float64)
        if arr.ndim not in (2, 3) or arr.shape[-1] != STATE_DIM:
            raise ValueError(
                f"{name}: expected an action chunk (H, {STATE_DIM}) or a batch (B, H, {STATE_DIM}), "
                f"got shape {arr.shape}"
            )
        if arr.shape[-2] < self.spec.executed_steps:
            raise ValueError(
                f"{name}: chunk has {arr.shape[-2]} steps but K·Δ = {self.spec.frames}·{self.spec.stride} = "
                f"{self.spec.executed_steps} are needed"
            )
        if not np.all(np.isfinite(arr)):
            raise ValueError(f"{name}: contains non-finite values")
        return arr

    def stride_aligned(self, chunks: NDArray[np.floating] | ActionChunk) -> NDArray[np.float64]:
        """(..., H_π, 14) → (..., K, 14): rows Δ−1, 2Δ−1, …, KΔ−1."""
        return self._as_chunks(chunks, "actions")[..., self.spec.stride_indices(), :]

    def geometry(
        self, stride_actions: NDArray[np.float64], previous_state: NDArray[np.floating] | None = None
    ) -> ControlGeometry:
        """Projected markers and trace segments for stride-aligned actions (B, K, 14)."""
        if stride_actions.ndim != 3 or stride_actions.shape[-1] != STATE_DIM:
            raise ValueError(f"stride_actions: expected shape (B, K, {STATE_DIM}), got {stride_actions.shape}")
        B, K = stride_actions.shape[:2]
        offset = 0
        seq = stride_actions
        if previous_state is not None:
            prev = np.asarray(previous_state, dtype=np.float64).reshape(-1, STATE_DIM)
            if prev.shape[0] != B or not np.all(np.isfinite(prev)):
                raise ValueError(
                    f"previous_state: expected {B} finite {STATE_DIM}-d state(s), got shape {np.shape(previous_state)}"
                )
            seq = np.concatenate([prev[:, None], stride_actions], axis=1)
            offset = 1
        N = K + offset
        points = self.kinematics.gripper_points(seq)  # (B, N, 2, 3) rig frame
        proj = self.camera.project_detailed(points.reshape(-1, 3))
        uv = proj.uv.reshape(B, N, 2, 2)
        usable = (proj.in_front & proj.in_valid_fov).reshape(B, N, 2) & np.all(np.isfinite(uv), axis=-1)
        visible = proj.visible.reshape(B, N, 2) & usable
        uv = np.where(usable[..., None], uv, 0.0)  # keep unusable entries finite for the drawing maths

        W, H = self.width, self.height
        radius = self.style.marker_radius(self.kinematics.gripper_openings(stride_actions), W, H)  # (B, K, 2)
        fuv = uv[:, offset:]
        overlaps = (
            (fuv[..., 0] > -0.5 - radius)
            & (fuv[..., 0] < W - 0.5 + radius)
            & (fuv[..., 1] > -0.5 - radius)
            & (fuv[..., 1] < H - 0.5 + radius)
        )
        marker = usable[:, offset:] & overlaps

        # Segment i joins index i−1 → i; index 0 has none. Clip to one pixel beyond the image.
        a = np.concatenate([uv[:, :1], uv[:, :-1]], axis=1)
        seg_a, seg_b, crosses = clip_segments(a, uv, (-1.0, -1.0), (W, H))
        seg_ok = crosses & usable & np.concatenate([np.zeros_like(usable[:, :1]), usable[:, :-1]], axis=1)
        seg_ok[:, 0] = False
        return ControlGeometry(uv, usable, visible, radius, marker, seg_a, seg_b, seg_ok, offset)

    # ------------------------------------------------------------------ drawing

    def _draw(self, geo: ControlGeometry, b: int, out: NDArray[np.uint8], layer: NDArray[np.uint8]) -> None:
        """Draw chunk ``b`` of ``geo`` into ``out`` (K, H, W, 3), zeroed by the caller.

        Each arm is drawn on its own layer (the left into ``out``, the right into the scratch ``layer``)
        and the layers are merged by per-channel maximum, so one arm's marker never hides the other's:
        with the default pure colours each arm keeps its own channel even where the markers overlap.
        """
        L = self.style.trace_length
        K = out.shape[0]
        off = geo.offset
        sa = np.rint(geo.seg_a[b] * _ONE).astype(np.int64).tolist()
        sb = np.rint(geo.seg_b[b] * _ONE).astype(np.int64).tolist()
        seg_ok = geo.seg_ok[b].tolist()
        centres = np.rint(geo.uv[b, off:] * _ONE).astype(np.int64).tolist()
        # OpenCV's anti-aliased disc covers about half a pixel more than its radius (measured: area =
        # π(r + 0.5)²), so draw r − 0.5 to make the covered area match the documented radius.
        radii = np.maximum(np.rint((geo.radius[b] - self._aa_pad) * _ONE), 1).astype(np.int64).tolist()
        marker = geo.marker[b].tolist()
        colors = self.style.colors
        line, circle, lt, th = cv2.line, cv2.circle, self._line_type, self._thickness
        layer.fill(0)
        for arm, target in ((0, out), (1, layer)):
            fade, color = self._fade_colors[arm], colors[arm]
            for k in range(K):
                img = target[k]
                e = k + off  # this frame's index in the extended sequence
                # Oldest (dimmest) segments first so newer ones are drawn on top; the marker last.
                for j in range(min(L, e) - 1, -1, -1):
                    i = e - j
                    if seg_ok[i][arm]:
                        line(img, sa[i][arm], sb[i][arm], fade[j], th, lt, _SHIFT)
                if marker[k][arm]:
                    circle(img, centres[k][arm], radii[k][arm], color, -1, lt, _SHIFT)
        np.maximum(out, layer, out=out)

    def render_batch(
        self,
        chunks: NDArray[np.floating],
        previous_states: NDArray[np.floating] | None = None,
    ) -> NDArray[np.uint8]:
        """Γ for a batch of chunks (B, H_π, 14) → uint8 (B, K, H, W, 3)."""
        arr = self._as_chunks(chunks, "actions")
        if arr.ndim == 2:
            raise ValueError(f"actions: render_batch expects (B, H, {STATE_DIM}), got {arr.shape}")
        return self.render_stride_aligned(arr[:, self.spec.stride_indices()], previous_states)

    def render_stride_aligned(
        self,
        stride_actions: NDArray[np.floating],
        previous_states: NDArray[np.floating] | None = None,
    ) -> NDArray[np.uint8]:
        """Γ from stride-aligned actions already picked out (B, K, 14) → uint8 (B, K, H, W, 3).

        Training clips store only the stride-aligned actions, so this is how Γ is drawn for them; it
        draws exactly what :meth:`render_batch` draws for full chunks with those rows.
        """
        arr = np.asarray(stride_actions, dtype=np.float64)
        if arr.ndim != 3 or arr.shape[1:] != (self.spec.frames, STATE_DIM):
            raise ValueError(f"stride_actions: expected shape (B, {self.spec.frames}, {STATE_DIM}), got {arr.shape}")
        if not np.all(np.isfinite(arr)):
            raise ValueError("stride_actions: contains non-finite values")
        geo = self.geometry(arr, previous_states)
        out = np.zeros((arr.shape[0], self.spec.frames, self.height, self.width, 3), dtype=np.uint8)
        layer = np.empty(out.shape[1:], dtype=np.uint8)
        for b in range(arr.shape[0]):
            self._draw(geo, b, out[b], layer)
        return out

    def __call__(
        self, chunk: NDArray[np.floating] | ActionChunk, previous_state: NDArray[np.floating] | None = None
    ) -> NDArray[np.uint8]:
        """Γ(A): one chunk (H_π, 14) → K control frames uint8 (K, H, W, 3).

        ``previous_state`` (14,), the state before the chunk, adds the trace segment into frame 0.
        """
        arr = self._as_chunks(chunk, "actions")
        if arr.ndim != 2:
            raise ValueError(f"actions: expected one chunk (H, {STATE_DIM}), got {arr.shape}; use render_batch")
        prev = None if previous_state is None else np.asarray(previous_state)[None]
        frames: NDArray[np.uint8] = self.render_batch(arr[None], prev)[0]
        return frames
