"""A wrist view that jumps ahead of its own camera: discontinuous arm motion, seen from the arm itself.

A wrist camera rides on its gripper, and the state's forward kinematics says where it is in every frame
(``RigConfig.wrist_cameras``). Between frames ``t - 1`` and ``t`` the table it sees moves by the plane
homography of that camera motion, so frame ``t - 1`` carried by it predicts frame ``t``. A world model that
skips ahead (the fault injector's ``teleport_arm``: every view runs ``s`` frames ahead of the state)
shows at ``t`` what the camera would see ``s`` frames later.

The test is a comparison, not a threshold on one residual: frame ``t`` is flagged when neither the
camera's own motion nor one frame of lag either way nor standing still explains it (median absolute
difference on the blurred grey image, over the pixels both frames show and the own gripper does not
cover, at least :attr:`Thresholds.ego_residual` levels) **and** the camera's pose some frames *later*
explains it :attr:`Thresholds.ego_ratio` times better. Comparing is what keeps clean episodes clean: a
camera low over a bowl sees it move by parallax the table plane does not model, and an arm's shadow
sweeps over the table — both spoil every candidate alike, and no far pose does better (measured on 75
clean varied episodes, seeds 4,900,000+: the largest ratio 1.2, where a single residual reached 8.9
levels). What makes the jump visible is the table's texture; on a uniform table every candidate looks
alike and the head view's arm check (``hallucination_checks.check_arms``) is the one that sees it.
"""

from __future__ import annotations

import cv2
import numpy as np
from numpy.typing import NDArray

from pilworld.config.rig import RigConfig
from pilworld.judges.hallucination_checks import ARM_MOTION, Finding, Thresholds, wrist_signature
from pilworld.judges.hallucination_scene import convex_hull, dilate
from pilworld.judges.hallucination_wrist import WristCamera

PLANE_Z = 0.0  # the table surface [m]: what most of a wrist view shows
_NOTHING = -1e4  # a pixel value that marks "nothing to compare" in a warped frame
_PROBES = np.array([[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 1.0], [0.5, 0.5], [0.25, 0.7]])  # × image size


def plane_homography(
    cam: WristCamera, T_to: NDArray[np.float64], T_from: NDArray[np.float64]
) -> NDArray[np.float64] | None:
    """The 3 × 3 map from pixels seen at pose ``T_from`` to pixels at ``T_to``, through the table plane; None
    where the plane is not in front of both."""
    probes = _PROBES * np.array([cam.width - 1.0, cam.height - 1.0])
    uv, ok = cam.reproject(probes, T_from, T_to, PLANE_Z)
    if not ok.all() or not np.isfinite(uv).all():
        return None
    H, _ = cv2.findHomography(probes, uv)
    return None if H is None else np.asarray(H, np.float64)


class _View:
    """One wrist view's frames, blurred grey, and the residual of predicting frame ``t`` from ``t - 1``."""

    def __init__(self, cam: WristCamera, frames: NDArray[np.uint8], poses: NDArray[np.float64], th: Thresholds):
        s = cam.width / 128.0
        self.cam, self.poses, self.th = cam, poses, th
        self.grey = np.stack(
            [cv2.GaussianBlur(f.mean(axis=2, dtype=np.float32), (0, 0), th.ego_blur_px * s) for f in frames]
        )
        # What moves with the camera rather than with the table: pixels dark in every frame of the episode
        # (its own gripper; the arm's own shadow), each part filled to its hull (what the fingers hold).
        self.own = dilate(convex_hull(wrist_signature(frames, th.signature_dark, len(frames))), 2 * s)
        self.min_valid = th.ego_min_shown * cam.width * cam.height
        self.source = np.where(self.own, np.float32(_NOTHING), self.grey)

    def residual(self, t: int, at: int, seen_from: int) -> float:
        """Frame ``t - 1`` (taken at pose ``seen_from``) carried to pose ``at``, against frame ``t``: the median
        absolute difference over the pixels both show; NaN when too few do."""
        H = plane_homography(self.cam, self.poses[seen_from], self.poses[at])  # pixels at `at` → at `seen_from`
        if H is None:
            return float("nan")
        size = (self.cam.width, self.cam.height)
        flags = cv2.INTER_LINEAR | cv2.WARP_INVERSE_MAP
        # The own gripper moves with the camera, not with the table: its pixels (marked far below 0, so any
        # interpolation touching one stays below 0) carry nothing, like the pixels from outside the frame.
        pred = cv2.warpPerspective(self.source[t - 1], H, size, flags=flags, borderValue=_NOTHING)
        shown = (pred >= 0) & ~self.own
        if shown.sum() < self.min_valid:
            return float("nan")
        return float(np.median(np.abs(pred - self.grey[t])[shown]))

    def jump(self, t: int) -> tuple[float, int] | None:
        """(near residual / best far residual, the far frame) when frame ``t`` jumped ahead, else None."""
        T = len(self.grey)
        # Standing still, the camera's own motion, a frame of lag either way: the first that explains the frame
        # ends the test (most frames), so the far poses are searched only where none does.
        r_near = float("inf")
        for a, b in ((t - 1, t - 1), (t, t - 1), (t - 1, max(t - 2, 0)), (min(t + 1, T - 1), t - 1)):
            r = self.residual(t, a, b)
            if r < self.th.ego_residual:
                return None
            if r < r_near:
                r_near = r
        if not np.isfinite(r_near):
            return None
        best, at = float("inf"), -1
        for j in range(2, self.th.ego_lookahead + 1):
            if t + j >= T:
                break
            r = self.residual(t, t + j, t - 1)
            if r < best:
                best, at = r, t + j
        if at < 0:
            return None
        ratio = r_near / max(best, self.th.ego_floor)
        return (ratio, at) if ratio >= self.th.ego_ratio else None


def check_wrist_motion(
    wrists: dict[str, NDArray[np.uint8]], rig: RigConfig, state: NDArray[np.floating], th: Thresholds
) -> Finding | None:
    """The first frame a wrist view shows what its camera would see frames later (see the module docstring)."""
    found: Finding | None = None
    size = (rig.image_size.height, rig.image_size.width)
    for name in sorted(wrists):
        frames = wrists[name]
        if name not in rig.wrist_cameras or frames.shape[1:3] != size or len(frames) < 3:
            continue
        cam = WristCamera.from_rig(rig, name)
        view = _View(cam, frames, cam.poses(rig, state), th)
        last = len(frames) if found is None else found.frame
        for t in range(1, last):
            hit = view.jump(t)
            if hit is not None:
                ratio, at = hit
                found = Finding(
                    t,
                    ARM_MOTION,
                    f"{name} jumped ahead of its camera: frame {t} shows the view from the pose of frame {at} "
                    f"({ratio:.1f}× closer than from its own)",
                )
                break
    return found
