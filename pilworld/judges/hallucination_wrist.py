"""Objects vanishing from a wrist view, with the camera's own motion accounted for.

A wrist camera moves with its gripper, so objects sweep through its view; from frame ``t - 1`` to ``t``
the camera pose changes by what the state's forward kinematics says (the camera sits at a fixed pose in
the TCP frame, ``RigConfig.wrist_cameras``). An object blob seen at ``t - 1`` is carried into frame
``t`` twice: as if it rested on the table (its pixels back-projected onto a plane at a typical object
mid-height and projected into the camera at ``t``) and as if it were held by this camera's gripper (it
stays where it was in the image). If either place still lies mostly inside the image, the object must
show there at ``t`` — or something (a finger, the other arm, another object) must cover it there.
Otherwise it vanished. Objects that another gripper may be carrying (seen in the head view next to a
closed gripper that moves) are left to the head view, since neither prediction holds for them, and so
are objects the head view still sees at ``t`` (knocked or dropped objects move faster than foreseen).

This catches what the head view cannot: an object deleted while a gripper hides it from the head
camera (the gripper is over it, or holds it).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import cv2
import numpy as np
from numpy.typing import NDArray

from pilworld.config.rig import RigConfig
from pilworld.judges.hallucination_checks import (
    OBJECT_DISAPPEARED,
    Finding,
    HeadScene,
    Thresholds,
    _centre,
    wrist_signature,
)
from pilworld.judges.hallucination_scene import (
    Mask,
    channel_max,
    convex_hull,
    dilate,
    learn_table,
    object_labels,
    table_mask,
)
from pilworld.types import LEFT_GRIP, RIGHT_GRIP

PLANE_Z = 0.022  # a typical object mid-height on the table [m] (cubes and blocks 17-28 mm, bowls ~20 mm)


@dataclass(frozen=True, eq=False)
class WristCamera:
    """A pinhole camera fixed to one gripper, as the simulated rig renders it (MuJoCo's ``fovy``)."""

    name: str
    arm: int  # 0 left, 1 right
    K: NDArray[np.float64]
    T_tcp_cam: NDArray[np.float64]  # camera frame (OpenCV axes) → TCP frame
    width: int
    height: int

    @staticmethod
    def from_rig(rig: RigConfig, name: str) -> WristCamera:
        cfg = rig.wrist_cameras[name]
        w, h = rig.image_size.width, rig.image_size.height
        f = h / (2.0 * math.tan(math.radians(cfg.fovy_deg) / 2.0))
        K = np.array([[f, 0.0, (w - 1) / 2.0], [0.0, f, (h - 1) / 2.0], [0.0, 0.0, 1.0]])
        return WristCamera(name, 0 if cfg.arm == "left" else 1, K, cfg.pose_in_tcp.matrix(), w, h)

    def poses(self, rig: RigConfig, state: NDArray[np.floating]) -> NDArray[np.float64]:
        """``(T, 4, 4)`` camera → rig-frame transforms for ``state`` ``(T, 14)``."""
        tcp = rig.kinematics.tcp_poses(np.asarray(state, dtype=np.float64))[:, self.arm]
        return np.asarray(tcp @ self.T_tcp_cam)

    def reproject(
        self, uv: NDArray[np.float64], T_from: NDArray[np.float64], T_to: NDArray[np.float64], z: float
    ) -> tuple[NDArray[np.float64], NDArray[np.bool_]]:
        """Pixels ``(N, 2)`` seen from ``T_from``, placed on the plane ``z``, as seen from ``T_to``."""
        rays = np.linalg.solve(self.K, np.c_[uv, np.ones(len(uv))].T).T  # camera frame, z = 1
        d = rays @ T_from[:3, :3].T
        o = T_from[:3, 3]
        with np.errstate(divide="ignore", invalid="ignore"):
            s = (z - o[2]) / d[:, 2]
        ok = np.isfinite(s) & (s > 0)
        X = o + np.where(ok, s, 0.0)[:, None] * d
        Xc = (X - T_to[:3, 3]) @ T_to[:3, :3]
        ok &= Xc[:, 2] > 0.01
        with np.errstate(divide="ignore", invalid="ignore"):
            proj = (Xc / Xc[:, 2:3]) @ self.K.T
        return proj[:, :2], ok


def _splat(uv: NDArray[np.float64], ok: NDArray[np.bool_], shape: tuple[int, int]) -> Mask:
    m = np.zeros(shape, bool)
    u = np.round(uv[ok, 0]).astype(int)
    v = np.round(uv[ok, 1]).astype(int)
    inside = (u >= 0) & (u < shape[1]) & (v >= 0) & (v < shape[0])
    m[v[inside], u[inside]] = True
    return dilate(m, 1)


def _carried_elsewhere(
    head: HeadScene, state: NDArray[np.floating], t: int, c: int, th: Thresholds, own_arm: int
) -> bool:
    """Is object ``c`` seen in the head view at ``t - 1`` next to the other arm's gripper, closed and moving?"""
    blob = head.labels[t - 1] == c + 1
    if not blob.any():
        return False
    uv = head.arms.tcp_uv
    for a, grip in enumerate((LEFT_GRIP, RIGHT_GRIP)):
        if a == own_arm:
            continue  # this camera's own gripper: a held object stays put in the image, which is checked
        near = dilate(head.arms.distal[a, t - 1], th.carry_reach_px * head.scale)
        moved = float(np.hypot(*(uv[a, t] - uv[a, t - 1])))
        if (blob & near).any() and float(state[t - 1, grip]) < th.closed_grip and moved >= 1.0:
            return True
    return False


def check_wrist_objects(
    head: HeadScene,
    wrists: dict[str, NDArray[np.uint8]],
    rig: RigConfig,
    state: NDArray[np.floating],
    th: Thresholds,
) -> Finding | None:
    """The first frame an object vanishes from a wrist view without leaving it or being covered."""
    if not head.classes:
        return None
    found: Finding | None = None
    for name, frames in wrists.items():
        if name not in rig.wrist_cameras or frames.shape[1:3] != (rig.image_size.height, rig.image_size.width):
            continue
        f = _check_view(head, WristCamera.from_rig(rig, name), frames, rig, state, th)
        if f is not None and (found is None or f.frame < found.frame):
            found = f
    return found


def _check_view(
    head: HeadScene,
    cam: WristCamera,
    frames: NDArray[np.uint8],
    rig: RigConfig,
    state: NDArray[np.floating],
    th: Thresholds,
) -> Finding | None:
    T = frames.shape[0]
    s = cam.width / 128.0
    labels = object_labels(frames, head.classes, th.faded_saturation)
    dark = channel_max(frames) < th.signature_dark
    table = table_mask(frames, learn_table(frames[0], (labels[0] > 0) | dark[0]))
    poses = cam.poses(rig, state)
    min_px = th.min_wrist_object_px * s * s
    near = th.wrist_step_px * s
    shape = (cam.height, cam.width)

    own_grip = np.asarray(state[:, LEFT_GRIP if cam.arm == 0 else RIGHT_GRIP], dtype=np.float64)

    def holding(t: int, t_to: int) -> bool:
        """Only a closed gripper holds anything (an open one's camera sees what rests on the table)."""
        return bool(min(own_grip[t], own_grip[t_to]) < th.closed_grip)

    def gone(t: int, c: int, blob: Mask, t_to: int) -> tuple[bool, Mask]:
        """Is ``blob`` of class ``c`` at ``t`` missing at ``t_to`` (where it should show, nothing covers it)?"""
        now = labels[t_to] == c + 1
        cover = dilate(~table[t_to] & ~now, 1)
        v, u = np.nonzero(blob)
        uv, ok = cam.reproject(np.c_[u, v].astype(np.float64), poses[t], poses[t_to], PLANE_Z)
        on_table = _splat(uv, ok, shape)
        k = int(blob.sum())
        if now.sum() >= 0.25 * k:
            return False, blob  # still in view somewhere (a held object swings in its grasp; a ring splits)
        if holding(t, t_to) and (
            (dilate(blob, near) & now).sum() >= 0.25 * k or (blob & cover).sum() >= th.wrist_covered_fraction * k
        ):
            return False, blob  # held by this camera's gripper (it stays put in the image), or covered there
        if on_table.sum() < 0.6 * k:
            return False, on_table  # resting on the table, the camera motion takes it (mostly) out of view
        k = int(on_table.sum())
        seen = (dilate(on_table, near) & now).sum() >= 0.25 * k
        return not (seen or (on_table & cover).sum() >= th.wrist_covered_fraction * k), on_table

    # What this gripper holds sits between its fingers: inside the hull of the gripper's own pixels.
    between = dilate(convex_hull(wrist_signature(frames, th.signature_dark)), near)
    for t in range(1, T - 1):
        opens = own_grip[t] - own_grip[t - 1] > 0.05
        for c, cls in enumerate(head.classes):
            prev = (labels[t - 1] == c + 1).astype(np.uint8)
            n, lab, stats, _ = cv2.connectedComponentsWithStats(prev, connectivity=8)
            for i in range(1, n):
                if stats[i, cv2.CC_STAT_AREA] < min_px:
                    continue
                blob = lab == i
                if opens and (blob & between).sum() >= 0.5 * stats[i, cv2.CC_STAT_AREA]:
                    continue  # this gripper opens on it: what it held drops, close to the camera, anywhere in view
                missing, where = gone(t - 1, c, blob, t)
                if not missing or _carried_elsewhere(head, state, t, c, th, cam.arm):
                    continue
                in_head = int((head.labels[t] == c + 1).sum())
                if in_head >= max(th.min_object_px * head.scale**2, 0.25 * int((head.labels[t - 1] == c + 1).sum())):
                    continue  # the head view still sees it: it moved on its own (knocked, dropped) faster than foreseen
                if gone(t - 1, c, blob, t + 1)[0]:
                    u, v = _centre(where)
                    return Finding(
                        t,
                        OBJECT_DISAPPEARED,
                        f"{cls.name} vanished from {cam.name} near ({u}, {v}), not covered or out of view",
                    )
    return None
