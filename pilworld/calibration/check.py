"""Checks of a head-camera calibration: FK-projected gripper points and board corners on held-out views.

* **Gripper points** (both arms' TCPs from FK of the measured state, ``DualArmKinematics.gripper_points``)
  are projected with the calibrated model. On a simulated rig the true camera is known, so the pixel
  error is exact; it is measured at the rig's image size (what the control video draws), e.g. 128×128.
  On a real rig the overlay (a cross per gripper: left red, right blue, as in the control video) is for
  a person to judge.
* **Board corners**: with the board mount from the hand-eye report, the corners FK predicts are compared
  with the detected ones: a held-out reprojection error of the whole chain (FK, mount, camera) that needs
  no ground truth, reported at the image resolution and scaled to the rig's.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import cv2
import numpy as np
import numpy.typing as npt

from calib.board import ChArUcoBoard
from calib.camera_model import CameraModel
from calib.detect import BoardDetector
from pilworld.calibration.recording import RecordedView
from pilworld.config.rig import RigConfig, letterbox
from pilworld.types import ARM_SIDES

__all__ = ["CheckResult", "check_views", "draw_overlay", "gripper_reprojection_errors"]

FloatArray = npt.NDArray[np.float64]
UInt8Array = npt.NDArray[np.uint8]

ARM_COLORS_RGB = {"left": (230, 40, 40), "right": (40, 90, 230)}  # the control video's colours


def gripper_reprojection_errors(
    rig: RigConfig, camera_true: CameraModel, T_cam_base: npt.ArrayLike, states: npt.ArrayLike
) -> dict[str, FloatArray]:
    """Per arm, pixel distances between the gripper points projected with ``T_cam_base`` and with the truth.

    ``camera_true`` sets the intrinsics and the image size the errors are measured at; ``states`` is
    ``(N, 14)``. Only points the true camera sees are counted.
    """
    points = rig.kinematics.gripper_points(np.asarray(states, dtype=np.float64).reshape(-1, 14))  # (N, 2, 3)
    uv_true, visible = camera_true.project(points)
    uv_est, _ = camera_true.with_pose(T_cam_base).project(points)
    err = np.linalg.norm(uv_est - uv_true, axis=-1)
    return {side: err[:, k][visible[:, k]] for k, side in enumerate(ARM_SIDES)}


def draw_overlay(
    image: UInt8Array,
    uv: FloatArray,
    visible: npt.NDArray[np.bool_],
    uv_true: FloatArray | None = None,
    board_uv: FloatArray | None = None,
) -> UInt8Array:
    """``image`` (RGB) with a cross per gripper at ``uv`` ``(2, 2)``, a circle at the truth and board dots."""
    out = np.ascontiguousarray(image if image.ndim == 3 else np.repeat(image[..., None], 3, axis=2)).copy()
    size = max(4, round(min(out.shape[:2]) / 40))
    thick = max(1, round(min(out.shape[:2]) / 400))
    shift = 4
    for k, side in enumerate(ARM_SIDES):
        if not visible[k]:
            continue
        color = ARM_COLORS_RGB[side]
        c = np.round(uv[k] * (1 << shift)).astype(int)
        for d in ((size, size), (size, -size)):
            a = (int(c[0] - d[0] * (1 << shift)), int(c[1] - d[1] * (1 << shift)))
            b = (int(c[0] + d[0] * (1 << shift)), int(c[1] + d[1] * (1 << shift)))
            cv2.line(out, a, b, color, thick, cv2.LINE_AA, shift)
        if uv_true is not None:
            t = np.round(uv_true[k] * (1 << shift)).astype(int)
            cv2.circle(out, (int(t[0]), int(t[1])), size * (1 << shift), (40, 200, 40), thick, cv2.LINE_AA, shift)
    if board_uv is not None:
        for p in np.round(board_uv * (1 << shift)).astype(int):
            cv2.circle(
                out, (int(p[0]), int(p[1])), max(1, size // 3) * (1 << shift), (250, 200, 0), -1, cv2.LINE_AA, shift
            )
    return out


@dataclass(frozen=True, eq=False)
class CheckResult:
    """Per-arm errors over the checked views and the overlay images."""

    image_size: tuple[int, int]  #: of the checked images
    rig_size: tuple[int, int]  #: the rig's image size (what the control video draws)
    gripper_err_px: dict[str, FloatArray]  #: per arm, vs the truth at the rig's size (empty without truth)
    board_err_px: dict[str, FloatArray]  #: per arm, FK-predicted minus detected corners at the image size
    overlays: dict[str, UInt8Array] = field(repr=False)  #: per view name, RGB

    def to_dict(self) -> dict[str, Any]:
        scale = self.rig_size[0] / self.image_size[0]
        out: dict[str, Any] = {"image_size": list(self.image_size), "rig_image_size": list(self.rig_size), "arms": {}}
        for side in ARM_SIDES:
            entry: dict[str, Any] = {}
            g = self.gripper_err_px.get(side)
            if g is not None and g.size:
                entry["gripper_points"] = int(g.size)
                entry["gripper_err_mean_px"] = float(g.mean())
                entry["gripper_err_max_px"] = float(g.max())
            b = self.board_err_px.get(side)
            if b is not None and b.size:
                rms = math.sqrt(float(np.mean(b**2)))
                entry["board_corners"] = int(b.size)
                entry["board_reproj_rms_px"] = rms
                entry["board_reproj_rms_px_at_rig_size"] = rms * scale
            if entry:
                out["arms"][side] = entry
        return out

    def lines(self) -> list[str]:
        w, h = self.rig_size
        rows = []
        for side, entry in self.to_dict()["arms"].items():
            parts = [f"{side:>5} arm:"]
            if "gripper_err_max_px" in entry:
                parts.append(
                    f"gripper points vs truth mean {entry['gripper_err_mean_px']:.3f} px, max "
                    f"{entry['gripper_err_max_px']:.3f} px at {w}x{h} ({entry['gripper_points']} points)"
                )
            if "board_reproj_rms_px" in entry:
                parts.append(
                    f"board corners by FK: RMS {entry['board_reproj_rms_px']:.3f} px at {self.image_size[0]}x"
                    f"{self.image_size[1]} = {entry['board_reproj_rms_px_at_rig_size']:.3f} px at {w}x{h} "
                    f"({entry['board_corners']} corners)"
                )
            rows.append(" ".join(parts) if len(parts) > 1 else f"{side:>5} arm: nothing to compare")
        return rows


def check_views(
    views: Sequence[RecordedView],
    camera: CameraModel,
    rig: RigConfig,
    *,
    truth_T_cam_base: npt.ArrayLike | None = None,
    board: ChArUcoBoard | None = None,
    T_tcp_board: Mapping[str, npt.ArrayLike] | None = None,
) -> CheckResult:
    """Project gripper points (and board corners, given ``board`` and ``T_tcp_board``) on each view.

    ``camera`` is the calibrated model at the images' resolution; ``truth_T_cam_base`` the true pose of a
    simulated camera (the same intrinsics are assumed).
    """
    rig_size = (rig.image_size.width, rig.image_size.height)
    est_small = letterbox(camera, *rig_size)
    true_small = None if truth_T_cam_base is None else est_small.with_pose(truth_T_cam_base)
    true_full = None if truth_T_cam_base is None else camera.with_pose(truth_T_cam_base)
    detector = BoardDetector(board) if board is not None else None
    grip: dict[str, list[FloatArray]] = {s: [] for s in ARM_SIDES}
    board_err: dict[str, list[FloatArray]] = {s: [] for s in ARM_SIDES}
    overlays: dict[str, UInt8Array] = {}
    size = (camera.width, camera.height)
    for view in views:
        if view.image_size != size:
            raise ValueError(
                f"view {view.name!r}: image is {view.image_size[0]}x{view.image_size[1]} but the camera model is "
                f"{size[0]}x{size[1]}"
            )
        points = rig.kinematics.gripper_points(view.state)  # (2, 3)
        uv, vis = camera.project(points)
        uv_true = true_full.project(points)[0] if true_full is not None else None
        if true_small is not None:
            for side, e in gripper_reprojection_errors(rig, true_small, camera.T_cam_base, view.state).items():
                grip[side].append(e)
        board_uv = None
        if detector is not None and board is not None and T_tcp_board is not None and view.arm in T_tcp_board:
            T = rig.kinematics.tcp_poses(view.state)[ARM_SIDES.index(view.arm)] @ np.asarray(T_tcp_board[view.arm])
            detection = detector.detect(view.gray(), name=view.name)
            if detection.n_corners:
                pts = board.corner_points()[detection.corner_ids] @ T[:3, :3].T + T[:3, 3]
                board_uv = camera.project(pts)[0]
                board_err[view.arm].append(np.linalg.norm(board_uv - detection.corners, axis=1))
        overlays[view.name] = draw_overlay(view.image, uv, vis, uv_true, board_uv)
    return CheckResult(
        image_size=size,
        rig_size=rig_size,
        gripper_err_px={s: np.concatenate(v) if v else np.zeros(0) for s, v in grip.items()},
        board_err_px={s: np.concatenate(v) if v else np.zeros(0) for s, v in board_err.items()},
        overlays=overlays,
    )
