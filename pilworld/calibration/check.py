"""Checks of a calibrated camera on held-out views, for either camera mount: what ``pilworld calibrate check`` runs.

Both compare what FK and the calibration predict with what the camera sees, view by view (docs/calibration.md,
"4. Check" and "Wrist cameras (eye-in-hand)"); the overlays are drawn by :mod:`.check_overlay`.

* **Head camera** (eye-to-hand, :func:`check_views`). *Gripper points*: both arms' TCPs from FK of the
  measured state (``DualArmKinematics.gripper_points``) are projected with the calibrated model. On a
  simulated rig the true camera is known, so the pixel error is exact; it is measured at the rig's image
  size (what the control video draws), e.g. 128×128. On a real rig the overlay is for a person to judge.
  *Board corners*: with the board mount from the hand-eye report, the corners FK predicts are compared with
  the detected ones: a held-out reprojection error of the whole chain (FK, mount, camera) that needs no
  ground truth, reported at the image resolution and scaled to the rig's.
* **Wrist camera** (eye-in-hand, :func:`check_wrist_views`). The board lies fixed on the table at
  ``T_rig_board``; the detected corners are compared with the corners projected through
  ``T_cam_rig = T_cam_tcp · FK(measured joints)⁻¹`` with ``T_cam_tcp`` and the intrinsics of the camera
  under test (the rig config's ``wrist_cameras.<name>.file``). It needs no ground truth either, so it is
  what a real rig reports too; measured at the images' resolution and scaled to the rig's image size.
  Held-out views come from the simulated rig (:func:`pilworld.calibration.sim_handeye.record_wrist_check_sim`)
  or from a recorded folder, with ``T_rig_board`` from the calibration report.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import numpy.typing as npt

from calib.board import ChArUcoBoard
from calib.camera_model import CameraModel
from calib.detect import BoardDetector
from pilworld.calibration.board_views import check_image_size
from pilworld.calibration.check_overlay import draw_overlay, draw_wrist_overlay
from pilworld.calibration.recording import RecordedView
from pilworld.config.rig import RigConfig, letterbox
from pilworld.geometry import invert_transform
from pilworld.kinematics.dual_arm import DualArmKinematics
from pilworld.types import ARM_LAYOUT, ARM_SIDES

__all__ = ["CheckResult", "WristCheckResult", "check_views", "check_wrist_views", "gripper_reprojection_errors"]

FloatArray = npt.NDArray[np.float64]
UInt8Array = npt.NDArray[np.uint8]


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


def _stats(err: FloatArray, scale: float) -> dict[str, Any]:
    rms = math.sqrt(float(np.mean(err**2)))
    mx = float(err.max())
    return {
        "corners": int(err.size),
        "rms_px": rms,
        "max_px": mx,
        "rms_px_at_rig_size": rms * scale,
        "max_px_at_rig_size": mx * scale,
    }


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
        check_image_size(view, camera)
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


@dataclass(frozen=True, eq=False)
class WristCheckResult:
    """Per-view corner errors of one wrist camera and the overlay images."""

    camera: str
    arm: str
    image_size: tuple[int, int]  #: of the checked images (the calibration resolution)
    rig_size: tuple[int, int]  #: the rig's image size
    errors_px: dict[str, FloatArray]  #: per view name, FK-predicted minus detected corner distances at image size
    skipped: dict[str, str] = field(default_factory=dict)  #: view name → why it was not checked
    overlays: dict[str, UInt8Array] = field(default_factory=dict, repr=False)  #: per view name, RGB

    @property
    def scale(self) -> float:
        """Image pixels → rig pixels (the letterbox scale)."""
        return min(self.rig_size[0] / self.image_size[0], self.rig_size[1] / self.image_size[1])

    @property
    def all_errors_px(self) -> FloatArray:
        return np.concatenate(list(self.errors_px.values())) if self.errors_px else np.zeros(0)

    def to_dict(self) -> dict[str, Any]:
        s = self.scale
        out: dict[str, Any] = {
            "camera": self.camera,
            "arm": self.arm,
            "image_size": list(self.image_size),
            "rig_image_size": list(self.rig_size),
            "views_checked": len(self.errors_px),
            "views": {name: _stats(e, s) for name, e in self.errors_px.items()},
            "skipped": dict(self.skipped),
        }
        every = self.all_errors_px
        if every.size:
            out["overall"] = _stats(every, s)
            out["worst_view_rms_px_at_rig_size"] = max(v["rms_px_at_rig_size"] for v in out["views"].values())
        return out

    def lines(self) -> list[str]:
        d = self.to_dict()
        (w, h), (rw, rh) = self.image_size, self.rig_size
        rows = [
            f"  {name}: {v['corners']} corners, RMS {v['rms_px']:.3f} px, max {v['max_px']:.3f} px at {w}x{h} "
            f"= RMS {v['rms_px_at_rig_size']:.4f} px, max {v['max_px_at_rig_size']:.4f} px at {rw}x{rh}"
            for name, v in d["views"].items()
        ]
        rows += [f"  {name}: skipped ({why})" for name, why in self.skipped.items()]
        if "overall" in d:
            o = d["overall"]
            rows.append(
                f"{self.camera} ({self.arm} arm): board corners by FK over {d['views_checked']} views "
                f"({o['corners']} corners): RMS {o['rms_px']:.3f} px, max {o['max_px']:.3f} px at {w}x{h} = "
                f"RMS {o['rms_px_at_rig_size']:.4f} px, max {o['max_px_at_rig_size']:.4f} px at {rw}x{rh}"
            )
        else:
            rows.append(f"{self.camera} ({self.arm} arm): no view showed the board; nothing to compare")
        return rows


def check_wrist_views(
    views: Sequence[RecordedView],
    camera: CameraModel,
    board: ChArUcoBoard,
    kinematics: DualArmKinematics,
    arm: str,
    T_rig_board: npt.ArrayLike,
    *,
    rig_size: tuple[int, int],
    name: str | None = None,
    overlays: bool = True,
) -> WristCheckResult:
    """Compare detected corners with those FK · ``T_tcp_cam`` · ``T_rig_board`` predicts, view by view.

    ``camera`` is the wrist camera under test at the images' resolution, ``T_cam_base = T_cam_tcp``
    (the ``wrist_cameras.<name>.file`` convention); only ``arm``'s views are checked. ``T_rig_board`` maps
    board-frame points into the rig frame.
    """
    cam_name = name or camera.name
    mine = [v for v in views if v.arm == arm]
    if not mine:
        raise ValueError(f"{cam_name}: no views with the {arm} arm (the arm carrying the camera)")
    size = (camera.width, camera.height)
    T_board = np.asarray(T_rig_board, dtype=np.float64).reshape(4, 4)
    T_cam_tcp = np.asarray(camera.T_cam_base, dtype=np.float64)
    mount = getattr(kinematics, arm)
    corners_rig = board.corner_points() @ T_board[:3, :3].T + T_board[:3, 3]
    detector = BoardDetector(board)
    errors: dict[str, FloatArray] = {}
    skipped: dict[str, str] = {}
    images: dict[str, UInt8Array] = {}
    for view in mine:
        check_image_size(view, camera)
        T_rig_tcp = mount.tcp_pose(view.state[ARM_LAYOUT[arm][0]])
        posed = camera.with_pose(T_cam_tcp @ invert_transform(T_rig_tcp))
        detection = detector.detect(view.gray(), name=view.name)
        if not detection.n_corners:
            skipped[view.name] = "no board corners detected"
            if overlays:
                images[view.name] = draw_wrist_overlay(view.image, np.zeros((0, 2)), np.zeros((0, 2)), "no board")
            continue
        uv, visible = posed.project(corners_rig[detection.corner_ids])
        if not np.all(visible):
            skipped[view.name] = "the predicted board lies behind the camera"
            continue
        err = np.linalg.norm(uv - detection.corners, axis=1)
        errors[view.name] = err
        if overlays:
            rms = math.sqrt(float(np.mean(err**2)))
            label = f"{view.name}: RMS {rms:.2f} px, max {float(err.max()):.2f} px at {size[0]}x{size[1]}"
            images[view.name] = draw_wrist_overlay(view.image, detection.corners, uv, label)
    return WristCheckResult(
        camera=cam_name,
        arm=arm,
        image_size=size,
        rig_size=rig_size,
        errors_px=errors,
        skipped=skipped,
        overlays=images,
    )
