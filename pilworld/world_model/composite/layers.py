"""The candidate layers of one chunk, computed from geometry alone (no learned weights).

For every view and future frame k (1 … K), from the current frame and state and the chunk's
stride-aligned actions:

* ``render``: the robot at its lagged pose (part ids, headlight shade, depth) — Γ⁺'s render;
* ``prior``: the static scene, the current frame reprojected into the future camera pose through the
  table plane with the robot's pixels removed — Γ⁺'s prior (with its validity);
* ``memory``: in the static head view, each pixel as last seen without the robot over it, in the history
  frames and the current one (the robot's pixels from renders at the remembered states) — what an arm
  uncovers when it moves away (the prior leaves it empty, since the current frame shows the arm there);
* ``hands``: where a hand can have changed the scene by frame k — in the head view, the pixels near the
  path of either tool point from now to frame k (objects move only where a gripper touches them; the
  composite keeps everything else as it was); the moving wrist views are all "near";
* ``carry`` (one per arm): what that gripper holds, moved rigidly with it. A gripper *holds from* the
  first frame its opening is below :data:`HOLD_MAX` (the current frame when it already rests on
  something) until the first frame it opens again; in between, the content around the tool point
  moves by the tool's rigid motion since the grasp (in the head view: a homography through the
  horizontal plane at the tool's height; in the arm's own wrist view: it stays where it was at the
  grasp). After the release the layer stays where the object was let go. Frames before the grasp,
  and views that cannot see the hand's content, have an invalid layer.

Whether the gripper really holds something (a missed grasp closes on air) is not decided here: the
network chooses per pixel between ``prior`` and ``carry`` from what it sees between the fingers.
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np
from numpy.typing import NDArray

from pilworld.config.rig import RigConfig
from pilworld.control_video.gamma_plus import GammaPlus
from pilworld.control_video.reprojection import plane_homography
from pilworld.control_video.robot_model import RobotModel
from pilworld.types import ARM_LAYOUT, STATE_DIM, ChunkSpec

U8 = NDArray[np.uint8]
F32 = NDArray[np.float32]
HOLD_MAX = 0.85  # grip below this: closed, or resting on an object (the policy's and the judge's threshold)
HAND_REACH = 0.09  # the head view's hand region: within this fraction of the image of the tool's path so far
SIDES = tuple(ARM_LAYOUT)  # ("left", "right")


@dataclass(frozen=True, eq=False)
class ChunkLayers:
    """Candidate layers of one chunk; every array has K on axis 0, views in ``views`` order."""

    views: tuple[str, ...]
    parts: dict[str, U8]  # (K, H, W) part ids (0 background … 4 right fingers)
    shade: dict[str, U8]  # (K, H, W) headlight shade of the robot, 0 off it
    depth: dict[str, F32]  # (K, H, W) camera-frame depth of the robot [m], 0 off it
    prior: dict[str, U8]  # (K, H, W, 3)
    prior_valid: dict[str, NDArray[np.bool_]]  # (K, H, W)
    carry: dict[str, dict[str, U8]]  # side → view → (K, H, W, 3)
    carry_valid: dict[str, dict[str, NDArray[np.bool_]]]  # side → view → (K, H, W)
    hands: dict[str, NDArray[np.bool_]]  # (K, H, W): where a hand can have changed the scene by frame k
    memory: dict[str, U8]  # (H, W, 3) per view: the latest remembered robot-free view of each pixel (head only)
    memory_valid: dict[str, NDArray[np.bool_]]  # (H, W)
    holding: F32  # (K, 2) 1 while a gripper holds (from its grasp frame until it opens), per side
    released: F32  # (K, 2) 1 after a hold ended within this chunk, per side
    poses: NDArray[np.float64]  # (K, 14) the lagged joint poses the render uses


def steps_from_stride(
    stride: NDArray[np.floating], state: NDArray[np.floating], spec: ChunkSpec
) -> NDArray[np.float64]:
    """A (KΔ, 14) per-step chunk from K stride-aligned actions, linear between them (from ``state``).

    The world model only receives the stride-aligned actions; the lag model needs the steps between.
    """
    s = np.asarray(stride, dtype=np.float64)
    seq = np.concatenate([np.asarray(state, dtype=np.float64)[None], s])  # at steps 0, Δ, 2Δ, …
    t = np.arange(1, spec.executed_steps + 1) / spec.stride  # in stride units
    lo = np.minimum(np.floor(t).astype(np.int64), len(seq) - 2)
    w = (t - lo)[:, None]
    out: NDArray[np.float64] = seq[lo] * (1 - w) + seq[lo + 1] * w
    return out


def hold_spans(grips: NDArray[np.floating]) -> tuple[int | None, int | None]:
    """(grasp index, release index) over a grip sequence ``[current, frame 1 … K]``; None if absent."""
    closed = np.asarray(grips) < HOLD_MAX
    if not closed.any():
        return None, None
    g = int(np.argmax(closed))
    after = np.flatnonzero(~closed[g:])
    return g, (g + int(after[0]) if after.size else None)


class LayerBuilder:
    """``builder(current_images, current_state, stride_actions) -> ChunkLayers`` for one rig.

    ``robot``: the robot model to render instead of the rig's (a mismatched model, for the stability
    probes; default: ``RobotModel.from_rig(rig)``)."""

    def __init__(self, rig: RigConfig, spec: ChunkSpec | None = None, robot: RobotModel | None = None) -> None:
        self.spec = spec or ChunkSpec()
        self.rig = rig
        self.gamma = GammaPlus(rig, "render+prior", spec=self.spec, robot=robot)
        self.cameras = self.gamma.cameras
        self.kinematics = rig.kinematics
        self.views = self.cameras.names
        self._wrist_of = {v.arm: v.name for v in self.cameras.views if v.arm is not None}

    def __call__(
        self,
        current_images: dict[str, U8],
        current_state: NDArray[np.floating],
        stride_actions: NDArray[np.floating],
        history_images: dict[str, U8] | None = None,
        history_states: NDArray[np.floating] | None = None,
        history_valid: NDArray[np.bool_] | None = None,
        resting: tuple[float | None, float | None] | None = None,
        with_carry: bool = True,
    ) -> ChunkLayers:
        """Layers of one chunk; ``history_*`` (H_h frames oldest first, their states and validity) feed ``memory``.

        ``resting``: per side (left, right), the opening its fingers rest at on a held object (None: not
        holding); default: any gripper whose measured opening is below :data:`HOLD_MAX` rests where it is.
        """
        state = np.asarray(current_state, dtype=np.float64)
        stride = np.asarray(stride_actions, dtype=np.float64)
        if state.shape != (STATE_DIM,) or stride.ndim != 2 or stride.shape[1] != STATE_DIM:
            raise ValueError(f"layers: expected state (14,) and actions (K, 14), got {state.shape} and {stride.shape}")
        chunk = steps_from_stride(stride, state, self.spec)
        for si, side in enumerate(SIDES):
            # Fingers already resting on something stay at that opening until the gripper opens: the render
            # must not close them through what they hold (the command says 0, the object says its width).
            grip_index = ARM_LAYOUT[side][1]
            rest = (state[grip_index] if state[grip_index] < HOLD_MAX else None) if resting is None else resting[si]
            if rest is not None:
                opened = np.flatnonzero(chunk[:, grip_index] >= HOLD_MAX)
                until = int(opened[0]) if opened.size else len(chunk)
                chunk[:until, grip_index] = np.maximum(chunk[:until, grip_index], rest)
        # The robot's pixels now, rendered once: Γ⁺'s prior, the memory and a grasp's wrist view all remove them.
        assert self.gamma.renderer is not None
        now_parts = self.gamma.renderer.render(state[None], depth=False, shaded=False).parts
        now_masks = {v: p[0] > 0 for v, p in now_parts.items()}
        cf = self.gamma(chunk, current_images=current_images, current_state=state, current_robot_masks=now_masks)
        assert cf.render is not None and cf.prior is not None
        assert cf.render.shaded is not None and cf.render.depth is not None
        poses = self.gamma_poses(chunk, state)
        K = poses.shape[0]
        seq = np.concatenate([state[None], poses])  # index 0 = now, i = frame i
        tcp = self.kinematics.tcp_poses(seq)  # (K+1, 2, 4, 4) T_rig_tcp
        holding = np.zeros((K, 2), dtype=np.float32)
        released = np.zeros((K, 2), dtype=np.float32)
        carry: dict[str, dict[str, U8]] = {}
        carry_valid: dict[str, dict[str, NDArray[np.bool_]]] = {}
        for si, side in enumerate(SIDES):
            grip_index = ARM_LAYOUT[side][1]
            g, r = hold_spans(seq[:, grip_index])
            carry[side], carry_valid[side] = {}, {}
            for view in self.cameras.views:
                h, w = view.model.height, view.model.width
                img = np.zeros((K, h, w, 3), dtype=np.uint8)
                ok = np.zeros((K, h, w), dtype=bool)
                carry[side][view.name], carry_valid[side][view.name] = img, ok
            if g is None or not with_carry:
                continue
            grasp_view: dict[str, tuple[U8, NDArray[np.bool_]]] = {}
            for i in range(max(g, 1), K + 1):
                held_until = i if r is None or i < r else r - 1  # frozen where it was let go
                holding[i - 1, si] = 1.0 if r is None or i < r else 0.0
                released[i - 1, si] = 0.0 if r is None or i < r else 1.0
                motion = tcp[held_until, si] @ np.linalg.inv(tcp[g, si])  # rig-frame rigid motion since the grasp
                for view in self.cameras.views:
                    name = view.name
                    if view.arm is None:
                        self._head_carry(
                            view,
                            current_images[name],
                            tcp[g, si],
                            tcp[held_until, si],
                            motion,
                            carry[side][name],
                            carry_valid[side][name],
                            i - 1,
                        )
                    elif view.arm == side:
                        # Held content is fixed in the holding arm's own wrist camera: as it was at the grasp.
                        if g == 0:
                            src = np.asarray(current_images[name])
                            carry[side][name][i - 1] = src
                            carry_valid[side][name][i - 1] = True
                        else:
                            if name not in grasp_view:
                                grasp_view[name] = self._view_at(current_images, state, seq[g], name, now_masks)
                            carry[side][name][i - 1], carry_valid[side][name][i - 1] = grasp_view[name]
        hands = self._hands(tcp)
        memory, memory_valid = self._memory(current_images, now_parts, history_images, history_states, history_valid)
        parts = cf.render.parts
        shade = {v: np.asarray(cf.render.shaded[v]).max(axis=-1) for v in self.views}
        return ChunkLayers(
            views=self.views,
            parts=parts,
            shade=shade,
            depth={v: cf.render.depth[v] for v in self.views},
            prior=cf.prior.images,
            prior_valid=cf.prior.valid,
            carry=carry,
            carry_valid=carry_valid,
            hands=hands,
            memory=memory,
            memory_valid=memory_valid,
            holding=holding,
            released=released,
            poses=poses,
        )

    def _view_at(
        self,
        current: dict[str, U8],
        state: NDArray[np.float64],
        q: NDArray[np.float64],
        view: str,
        now_masks: dict[str, NDArray[np.bool_]],
    ) -> tuple[U8, NDArray[np.bool_]]:
        """The current frame of ``view`` reprojected to the pose ``q``, keeping what is near the fingers there.

        Γ⁺'s prior leaves the future robot's surroundings empty; what a gripper grasps sits exactly there.
        """
        assert self.gamma.reprojector is not None
        prior = self.gamma.reprojector(current, state, q[None], now_masks, None)
        return prior.images[view][0], prior.valid[view][0]

    def _hands(self, tcp: NDArray[np.float64]) -> dict[str, NDArray[np.bool_]]:
        K = tcp.shape[0] - 1
        out: dict[str, NDArray[np.bool_]] = {}
        for view in self.cameras.views:
            h, w = view.model.height, view.model.width
            if view.arm is not None:
                out[view.name] = np.ones((K, h, w), bool)
                continue
            uv, _ = view.model.project(tcp[:, :, :3, 3].reshape(-1, 3))
            uv = np.nan_to_num(uv.reshape(K + 1, 2, 2), nan=-1e4).clip(-1e4, 1e4)
            radius = max(1, round(HAND_REACH * min(h, w)))
            canvas = np.zeros((h, w), np.uint8)
            masks = np.zeros((K, h, w), bool)
            for i in range(1, K + 1):
                for side in range(2):
                    a = tuple(int(np.rint(c)) for c in uv[i - 1, side])
                    b = tuple(int(np.rint(c)) for c in uv[i, side])
                    cv2.line(canvas, a, b, 1, thickness=2 * radius + 1)
                masks[i - 1] = canvas > 0
            out[view.name] = masks
        return out

    def _memory(
        self,
        current: dict[str, U8],
        now_parts: dict[str, U8],
        history: dict[str, U8] | None,
        states: NDArray[np.floating] | None,
        valid: NDArray[np.bool_] | None,
    ) -> tuple[dict[str, U8], dict[str, NDArray[np.bool_]]]:
        out: dict[str, U8] = {}
        ok: dict[str, NDArray[np.bool_]] = {}
        for view in self.cameras.views:
            h, w = view.model.height, view.model.width
            out[view.name] = np.zeros((h, w, 3), np.uint8)
            ok[view.name] = np.zeros((h, w), bool)
        head = next((v.name for v in self.cameras.views if v.arm is None), None)
        if head is None:
            return out, ok
        frames = [] if history is None or states is None else list(zip(history[head], states, strict=True))
        if valid is not None and frames:
            frames = [f for f, keep in zip(frames, np.asarray(valid, bool), strict=True) if keep]
        assert self.gamma.renderer is not None
        parts = (
            []
            if not frames
            else list(
                self.gamma.renderer.render(
                    np.stack([np.asarray(st, np.float64) for _, st in frames]), depth=False, shaded=False, views=[head]
                ).parts[head]
            )
        )
        frames.append((np.asarray(current[head]), None))
        parts.append(now_parts[head][0])  # the current frame last: it wins where it sees the scene
        kernel = np.ones((5, 5), np.uint8)
        mem, seen = out[head], ok[head]
        for (img, _), p in zip(frames, parts, strict=True):
            free = cv2.dilate((p > 0).astype(np.uint8), kernel) == 0
            mem[free] = np.asarray(img)[free]
            seen |= free
        return out, ok

    def gamma_poses(self, chunk: NDArray[np.float64], state: NDArray[np.float64]) -> NDArray[np.float64]:
        from pilworld.control_video.lag import lagged_poses

        return lagged_poses(chunk, state, self.spec, self.gamma.lag_steps)

    @staticmethod
    def _head_carry(view, image, T_grasp, T_now, motion, out, ok, k) -> None:  # type: ignore[no-untyped-def]
        """Warp the current head frame so what sat at the tool point at the grasp follows the tool."""
        model = view.model
        T_cam = model.T_cam_base
        z_src = float(T_grasp[2, 3])
        z_dst = float(T_now[2, 3])
        H_src = plane_homography(model.K, T_cam, z_src)  # plane (x, y, 1) at the grasp height → source pixels
        H_dst = plane_homography(model.K, T_cam, z_dst)
        A = np.eye(3)
        A[:2, :2] = motion[:2, :2]
        A[:2, 2] = motion[:2, 3]
        H = H_dst @ A @ np.linalg.inv(H_src)  # source pixels → target pixels
        h, w = model.height, model.width
        src = np.asarray(image)
        out[k] = cv2.warpPerspective(src, H, (w, h), flags=cv2.INTER_LINEAR, borderMode=cv2.BORDER_CONSTANT)
        mask = cv2.warpPerspective(np.full((h, w), 255, np.uint8), H, (w, h), flags=cv2.INTER_NEAREST)
        ok[k] = mask > 0
