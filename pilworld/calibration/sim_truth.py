"""How far a simulated calibration is from the simulator's ground truth, for either camera mount.

* Head camera (eye-to-hand, :func:`truth_errors`): the truth is ``T_cam_base`` from
  ``rig.head_camera_model`` and each arm's board mount (:class:`pilworld.calibration.recording.SimTruth`);
  the errors are the camera pose's, the mounts' and the FK gripper points' of held-out poses drawn at the
  rig's image size.
* Wrist camera (eye-in-hand, :func:`wrist_truth_errors`): the truth is the camera's ``pose_in_tcp`` and the
  table board's pose (:class:`WristTruth`, kept in a recording's ``poses.json`` under :data:`TRUTH_KEY`);
  the errors are the mount's, the board pose's and the board corners' drawn at the rig's image size.

See docs/calibration.md, "Measured on the simulated rig" and "Wrist cameras (eye-in-hand)".
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any, Final

import numpy as np
import numpy.typing as npt

from calib.rotations import pose_difference
from pilworld.calibration.check import gripper_reprojection_errors
from pilworld.calibration.recording import SimTruth
from pilworld.calibration.sim_cameras import sim_wrist_camera
from pilworld.calibration.solve import WristHandEye
from pilworld.calibration.solve_arms import HandEyeOutcome
from pilworld.config.rig import RigConfig
from pilworld.geometry import invert_transform

__all__ = ["TRUTH_KEY", "WristTruth", "truth_errors", "truth_line", "wrist_truth_errors", "wrist_truth_line"]

FloatArray = npt.NDArray[np.float64]

#: Key of the eye-in-hand ground truth in a recording's ``poses.json`` (simulated rigs only).
TRUTH_KEY: Final = "sim_truth_eye_in_hand"


@dataclass(frozen=True, eq=False)
class WristTruth:
    """The ground truth of a simulated wrist calibration."""

    camera: str
    T_tcp_cam: FloatArray  #: ``(4, 4)`` camera frame → TCP frame
    T_rig_board: FloatArray  #: ``(4, 4)`` board frame → rig frame

    def to_dict(self) -> dict[str, Any]:
        return {"camera": self.camera, "T_tcp_cam": self.T_tcp_cam.tolist(), "T_rig_board": self.T_rig_board.tolist()}

    @classmethod
    def from_extra(cls, extra: Mapping[str, Any]) -> WristTruth | None:
        """The truth kept in a recording's free-form metadata, or None (a real rig's recording)."""
        doc = extra.get(TRUTH_KEY)
        if not isinstance(doc, Mapping):
            return None
        return cls(
            camera=str(doc["camera"]),
            T_tcp_cam=np.asarray(doc["T_tcp_cam"], dtype=np.float64).reshape(4, 4),
            T_rig_board=np.asarray(doc["T_rig_board"], dtype=np.float64).reshape(4, 4),
        )


def truth_errors(rig: RigConfig, outcome: HandEyeOutcome, truth: SimTruth, states: npt.ArrayLike) -> dict[str, Any]:
    """True errors of a simulated head-camera calibration: camera pose, board mounts and held-out gripper points."""
    dt, dr = pose_difference(outcome.T_cam_base, truth.T_cam_base)
    small = rig.head_camera_model  # the true camera at the rig's image size
    errs = gripper_reprojection_errors(rig, small, outcome.T_cam_base, states)
    every = np.concatenate(list(errs.values()))
    out: dict[str, Any] = {
        "translation_err_mm": dt * 1e3,
        "rotation_err_deg": dr,
        "gripper_reproj_err_px": float(every.max()) if every.size else math.nan,
        "gripper_reproj_mean_px": float(every.mean()) if every.size else math.nan,
        "gripper_points": int(every.size),
        "gripper_image_size": [small.width, small.height],
        "gripper_reproj_err_px_per_arm": {s: float(e.max()) if e.size else math.nan for s, e in errs.items()},
        "board_mount_err": {},
    }
    for side, T in outcome.T_tcp_board.items():
        if side in truth.T_tcp_board:
            mt, mr = pose_difference(T, truth.T_tcp_board[side])
            out["board_mount_err"][side] = {"translation_mm": mt * 1e3, "rotation_deg": mr}
    return out


def truth_line(errors: dict[str, Any]) -> str:
    """:func:`truth_errors` in one line."""
    w, h = errors["gripper_image_size"]
    return (
        f"vs the simulator's truth: T_cam_base off by {errors['translation_err_mm']:.3f} mm and "
        f"{errors['rotation_err_deg']:.4f}°; held-out gripper points off by max {errors['gripper_reproj_err_px']:.3f}"
        f" px (mean {errors['gripper_reproj_mean_px']:.3f} px) at {w}x{h}"
    )


def wrist_truth_errors(rig: RigConfig, result: WristHandEye, truth: WristTruth) -> dict[str, Any]:
    """True errors of a simulated wrist calibration: the mount, the board pose, the board corners drawn.

    ``board_reproj_err_px``: the largest distance, at the rig's image size (what the control video
    draws), between the board corners projected with the estimated and with the true camera at every
    calibration pose (measured joints).
    """
    dt, dr = pose_difference(result.T_tcp_cam, truth.T_tcp_cam)
    bt, br = pose_difference(result.T_rig_board, truth.T_rig_board)
    small = sim_wrist_camera(rig, truth.camera, rig.image_size.width)
    worst = 0.0
    for view in result.views:
        corners = view.board_points @ truth.T_rig_board[:3, :3].T + truth.T_rig_board[:3, 3]
        T_cam_rig_true = invert_transform(view.T_base_gripper @ truth.T_tcp_cam)
        T_cam_rig_est = invert_transform(view.T_base_gripper @ result.T_tcp_cam)
        uv_true = small.with_pose(T_cam_rig_true).project(corners)[0]
        uv_est = small.with_pose(T_cam_rig_est).project(corners)[0]
        worst = max(worst, float(np.linalg.norm(uv_est - uv_true, axis=1).max()))
    return {
        "translation_err_mm": dt * 1e3,
        "rotation_err_deg": dr,
        "board_pose_err": {"translation_mm": bt * 1e3, "rotation_deg": br},
        "board_reproj_err_px": worst,
        "board_reproj_image_size": [small.width, small.height],
    }


def wrist_truth_line(errors: dict[str, Any]) -> str:
    """:func:`wrist_truth_errors` in one line."""
    w, h = errors["board_reproj_image_size"]
    return (
        f"vs the simulator's truth: T_tcp_cam off by {errors['translation_err_mm']:.3f} mm and "
        f"{errors['rotation_err_deg']:.4f}°; board corners drawn off by max {errors['board_reproj_err_px']:.4f} px "
        f"at {w}x{h}"
    )
