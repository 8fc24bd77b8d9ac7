"""The board in each recorded view: detected corners, the board's PnP pose and the arm's FK pose.

This is the input of every hand-eye solve, whatever the camera mount: the ChArUco corners are detected
(:class:`calib.detect.BoardDetector`) and PnP with the known intrinsics gives ``T_cam_board``; FK of the
*measured* joints of the view's arm gives ``T_base_gripper`` (rig frame). Views with too few corners or a
bad PnP fit are skipped with the reason (docs/calibration.md, "3. Hand-eye").
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Final

import cv2
import numpy as np
import numpy.typing as npt

from calib.board import ChArUcoBoard
from calib.camera_model import CameraModel
from calib.detect import BoardDetector
from calib.rotations import rigid
from pilworld.calibration.recording import RecordedView
from pilworld.kinematics.dual_arm import DualArmKinematics
from pilworld.types import ARM_LAYOUT

__all__ = ["MAX_PNP_RMS_PX", "MIN_CORNERS", "HandEyeView", "check_image_size", "detect_views"]

FloatArray = npt.NDArray[np.float64]

MIN_CORNERS: Final = 8  #: a view needs this many detected corners (and at least half the board's)
MAX_PNP_RMS_PX: Final = 2.0  #: a view whose own PnP leaves more than this is a bad detection


@dataclass(frozen=True, eq=False)
class HandEyeView:
    """One usable view: FK pose, PnP pose and the detected corners."""

    name: str
    T_base_gripper: FloatArray
    T_cam_board: FloatArray
    board_points: FloatArray
    image_points: FloatArray


def check_image_size(view: RecordedView, camera: CameraModel, advice: str = "") -> None:
    """``ValueError`` if ``view``'s image is not at ``camera``'s resolution (``advice`` is appended)."""
    if view.image_size != (camera.width, camera.height):
        raise ValueError(
            f"view {view.name!r}: image is {view.image_size[0]}x{view.image_size[1]} but the camera model is "
            f"{camera.width}x{camera.height}{advice}"
        )


def detect_views(
    views: Sequence[RecordedView], camera: CameraModel, board: ChArUcoBoard, kinematics: DualArmKinematics, arm: str
) -> tuple[list[HandEyeView], dict[str, str]]:
    """The usable views of ``arm`` (FK of its measured joints) and the skipped ones with the reason."""
    detector = BoardDetector(board)
    mount = getattr(kinematics, arm)
    min_corners = max(MIN_CORNERS, board.n_corners // 2)
    used: list[HandEyeView] = []
    skipped: dict[str, str] = {}
    for view in views:
        check_image_size(view, camera, "; calibrate intrinsics at the resolution of the hand-eye images")
        detection = detector.detect(view.gray(), name=view.name)
        if detection.n_corners < min_corners:
            skipped[view.name] = f"{detection.n_corners} corners detected (need {min_corners})"
            continue
        obj, img = detection.object_image_points()
        ok, rvec, tvec = cv2.solvePnP(obj, img, camera.K, camera.dist, flags=cv2.SOLVEPNP_ITERATIVE)
        if not ok:
            skipped[view.name] = "PnP failed"
            continue
        proj, _ = cv2.projectPoints(obj, rvec, tvec, camera.K, camera.dist)
        rms = math.sqrt(float(np.mean(np.sum((proj.reshape(-1, 2) - img) ** 2, axis=1))))
        if rms > MAX_PNP_RMS_PX:
            skipped[view.name] = f"PnP reprojection RMS {rms:.2f} px (> {MAX_PNP_RMS_PX} px): a bad detection"
            continue
        T_cam_board = rigid(cv2.Rodrigues(rvec)[0], tvec)
        T_base_gripper = mount.tcp_pose(view.state[ARM_LAYOUT[arm][0]])
        used.append(HandEyeView(view.name, T_base_gripper, T_cam_board, obj, img))
    return used, skipped
