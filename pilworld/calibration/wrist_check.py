"""Check of a calibrated wrist camera (eye-in-hand): FK-predicted board corners on held-out views.

The board lies fixed on the table at ``T_rig_board``. For every held-out view of the wrist camera the
detected ChArUco corners are compared with the corners projected through

``T_cam_rig = T_cam_tcp · FK(measured joints)⁻¹``,  corners in the rig frame ``= T_rig_board · X_board``

with ``T_cam_tcp`` and the intrinsics from the calibrated camera under test (the rig config's
``wrist_cameras.<name>.file``). The pixel error is a held-out reprojection error of the whole chain
(FK, mount, intrinsics, board pose): it needs no ground truth, so it is what a real rig reports too.
It is measured at the images' (calibration) resolution and scaled to the rig's image size (what the
control video draws).

* **Simulated rig** (:func:`record_wrist_check_sim`): the wrist planner chooses new camera poses (seed
  ``seed + HELD_OUT_SEED_OFFSET``, so not the calibration's), the arm moves there through the ``Robot``
  contract and the camera renders the :class:`simrig.table_board.TableBoard`, whose pose is known
  exactly.
* **Recorded folder**: the views a wrist calibration saves (``NNN.png`` + ``poses.json``) or new ones in the
  same format; ``T_rig_board`` then comes from the calibration report (its ``T_rig_board``).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Any

import cv2
import numpy as np
import numpy.typing as npt

from calib.board import ChArUcoBoard
from calib.camera_model import CameraModel
from calib.detect import BoardDetector
from pilworld.calibration.collect import collect_views
from pilworld.calibration.plan import WristPlannerSettings, plan_wrist_poses
from pilworld.calibration.recording import RecordedView, Recording
from pilworld.calibration.sim_handeye import DEFAULT_BOARD, HELD_OUT_SEED_OFFSET
from pilworld.calibration.wrist_sim import TRUTH_KEY, WristTruth, _park_objects, sim_wrist_camera, wrist_arm
from pilworld.config.rig import RigConfig
from pilworld.geometry import invert_transform
from pilworld.kinematics.dual_arm import DualArmKinematics
from pilworld.types import ARM_LAYOUT
from simrig.robot import SimRobot
from simrig.table_board import TableBoard

__all__ = ["WristCheckResult", "check_wrist_views", "draw_wrist_overlay", "record_wrist_check_sim"]

FloatArray = npt.NDArray[np.float64]
UInt8Array = npt.NDArray[np.uint8]

DETECTED_RGB = (40, 200, 40)  #: detected corners: green circles
PROJECTED_RGB = (230, 40, 40)  #: FK-projected corners: red crosses


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


def draw_wrist_overlay(image: UInt8Array, detected: FloatArray, projected: FloatArray, label: str = "") -> UInt8Array:
    """``image`` (RGB) with the detected corners (green circles), the projected ones (red crosses) and a label."""
    out = np.ascontiguousarray(image if image.ndim == 3 else np.repeat(image[..., None], 3, axis=2)).copy()
    size = max(3, round(min(out.shape[:2]) / 80))
    thick = max(1, round(min(out.shape[:2]) / 500))
    shift = 4
    one = 1 << shift
    for p in np.round(np.asarray(detected) * one).astype(int):
        cv2.circle(out, (int(p[0]), int(p[1])), size * one, DETECTED_RGB, thick, cv2.LINE_AA, shift)
    for p in np.round(np.asarray(projected) * one).astype(int):
        for d in ((size, size), (size, -size)):
            a = (int(p[0] - d[0] * one), int(p[1] - d[1] * one))
            b = (int(p[0] + d[0] * one), int(p[1] + d[1] * one))
            cv2.line(out, a, b, PROJECTED_RGB, thick, cv2.LINE_AA, shift)
    if label:
        scale = max(0.35, min(out.shape[:2]) / 1200)
        cv2.putText(
            out, label, (6, 6 + round(22 * scale)), cv2.FONT_HERSHEY_SIMPLEX, scale, (255, 255, 255), 1, cv2.LINE_AA
        )
    return out


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
        if view.image_size != size:
            raise ValueError(
                f"view {view.name!r}: image is {view.image_size[0]}x{view.image_size[1]} but the camera model is "
                f"{size[0]}x{size[1]}"
            )
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


def record_wrist_check_sim(
    rig: RigConfig,
    camera: str,
    *,
    board: ChArUcoBoard | None = None,
    poses: int = 6,
    seed: int = 0,
    resolution: int = 1024,
    log: Callable[[str], None] | None = None,
) -> tuple[Recording, FloatArray]:
    """Held-out wrist-camera views of the table board on the simulated rig; returns them and ``T_rig_board``.

    ``seed`` is the calibration's: the planner runs with ``seed + HELD_OUT_SEED_OFFSET``. It plans with the
    camera's designed mount (so a wrong calibration is checked on the same views as a good one) and skips
    the motion test (these views calibrate nothing). The rendering is the true camera at ``resolution``
    pixels wide; the recording carries the truth like :func:`pilworld.calibration.wrist_sim.record_sim_wrist`.
    """
    if isinstance(poses, bool) or not isinstance(poses, int) or poses < 1:
        raise ValueError(f"--poses: expected a number of camera poses >= 1, got {poses!r}")
    board = board or ChArUcoBoard.from_yaml(DEFAULT_BOARD)
    arm = wrist_arm(rig, camera)
    cam = sim_wrist_camera(rig, camera, resolution)
    table = TableBoard.for_arm(board, arm)
    planner_seed = seed + HELD_OUT_SEED_OFFSET
    with SimRobot(rig, table_board=table) as robot:
        _park_objects(robot)
        state = np.asarray(robot.observe().state, dtype=np.float64)
        gripper = getattr(rig.arms, arm).gripper.max_opening_m
        plan = plan_wrist_poses(
            rig.kinematics,
            cam,
            board,
            table.T_rig_board,
            arm,
            state,
            WristPlannerSettings(poses=poses),
            planner_seed,
            max_opening_m=gripper,
            for_calibration=False,
        )
        if log is not None:
            log(f"{camera} ({arm} arm): {len(plan.poses)} held-out camera poses (planner seed {planner_seed})")

        def capture() -> UInt8Array:
            return robot.render(camera, cam.width, cam.height)

        views = collect_views(robot, plan, capture, log=log)
    T_rig_board = np.array(table.T_rig_board, dtype=np.float64)
    truth = WristTruth(camera=camera, T_tcp_cam=rig.wrist_cameras[camera].pose_in_tcp.matrix(), T_rig_board=T_rig_board)
    recording = Recording(
        rig=rig.name,
        board=board,
        views=tuple(views),
        camera=cam.with_pose(np.eye(4)),
        extra={
            "source": "simulated rig",
            "calibration": "eye_in_hand_check",
            "camera": camera,
            "seed": planner_seed,
            "resolution": resolution,
            TRUTH_KEY: truth.to_dict(),
        },
    )
    return recording, T_rig_board
