"""``pilworld calibrate check`` end to end, for either camera mount: held-out views in, errors and overlays out.

The held-out views come from a recorded folder, from a hardware rig's robot (the command's own collector,
:attr:`CheckRequest.collect`) or, by default, from new poses on the simulated rig (another planner seed
than the calibration's). Then, by the camera (docs/calibration.md, "4. Check" and "Wrist cameras (eye-in-hand)"):

* the **head camera** (eye-to-hand): FK-projected gripper points per arm (against the truth when it is
  known) and, with the hand-eye report's board mounts, the board corners by FK
  (:func:`.check.check_views`);
* a **wrist camera** (eye-in-hand): the board corners FK · ``T_tcp_cam`` · ``T_rig_board`` predicts against
  the detected ones, per view (:func:`.check.check_wrist_views`); ``T_rig_board`` from the calibration
  report (a recorded folder) or the simulated table board.

It prints the errors, writes an overlay per view and ``check.json`` to ``out``, and says whether an error
at the rig's image size exceeds ``max_px`` (the command then exits 1).
"""

from __future__ import annotations

import json
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import cv2
import numpy as np
import numpy.typing as npt

from calib.board import ChArUcoBoard
from calib.camera_model import CameraModel
from pilworld.calibration.check import check_views, check_wrist_views
from pilworld.calibration.recording import Recording
from pilworld.calibration.sim_cameras import sim_calibration_camera, sim_wrist_camera, wrist_arm
from pilworld.calibration.sim_handeye import DEFAULT_BOARD, record_sim, record_wrist_check_sim
from pilworld.calibration.sim_truth import WristTruth
from pilworld.config.rig import RigConfig
from pilworld.types import HEAD_VIEW

__all__ = ["CheckOutcome", "CheckRequest", "run_check"]

FloatArray = npt.NDArray[np.float64]
UInt8Array = npt.NDArray[np.uint8]
Log = Callable[[str], None]


@dataclass(frozen=True)
class CheckRequest:
    """What ``pilworld calibrate check`` was asked (its flags, typed)."""

    rig_path: Path
    rig: RigConfig
    camera: str = HEAD_VIEW  #: the head camera, or a wrist camera's name
    camera_model: Path | None = None  #: the calibration under test (default: the rig's file, else the design)
    handeye_report: Path | None = None  #: head camera: the hand-eye report with the board mounts
    report: Path | None = None  #: the calibration report (a wrist camera's holds T_rig_board)
    images: Path | None = None  #: a recorded folder of held-out views
    arm: str = "both"  #: head camera: the arms to move
    poses: int = 6  #: held-out poses per arm
    seed: int = 1  #: planner seed of the held-out poses
    out: Path | None = None  #: folder for the overlays and check.json
    max_px: float | None = None
    #: a hardware rig's collector of held-out head-camera views (it moves the robot)
    collect: Callable[[], Recording] | None = None


@dataclass(frozen=True)
class CheckOutcome:
    """The summary ``check.json`` holds and, when an error exceeds ``max_px``, why the check failed."""

    summary: dict[str, Any]
    failure: str | None


def run_check(request: CheckRequest, log: Log) -> CheckOutcome:
    """Check the calibration on held-out views, write the overlays and say what was found with ``log``."""
    if request.camera != HEAD_VIEW:
        return _wrist(request, log)
    return _head(request, log)


def _beside(model_path: Path | None) -> Path | None:
    """The report ``calibrate handeye`` wrote beside a camera model, if there is one."""
    if model_path is not None and model_path.with_suffix(".json").is_file():
        return model_path.with_suffix(".json")
    return None


def _write(out: Path | None, overlays: dict[str, UInt8Array], summary: dict[str, Any], log: Log) -> None:
    if out is None:
        return
    out.mkdir(parents=True, exist_ok=True)
    for name, image in overlays.items():
        cv2.imwrite(str(out / f"check_{Path(name).stem}.png"), cv2.cvtColor(image, cv2.COLOR_RGB2BGR))
    (out / "check.json").write_text(json.dumps(summary, indent=1) + "\n", encoding="utf-8")
    log(f"wrote {len(overlays)} overlays and check.json to {out}")


def _head(request: CheckRequest, log: Log) -> CheckOutcome:
    """The head camera: gripper points and, with the board mounts, board corners per arm."""
    rig = request.rig
    file = rig.head_camera.file
    if request.camera_model is not None:
        camera = CameraModel.from_yaml(request.camera_model)
    elif file is not None:
        camera = CameraModel.from_yaml(file)
    else:
        camera = sim_calibration_camera(rig, 1024)  # a designed camera: checks the pipeline, not a calibration
    model_path = request.camera_model or (Path(file) if file else None)
    report_path = request.handeye_report or request.report or _beside(model_path)
    mounts: dict[str, Any] | None = None
    if report_path is not None:
        doc = json.loads(Path(report_path).read_text(encoding="utf-8"))
        mounts = {a: np.asarray(T, dtype=np.float64) for a, T in doc.get("T_tcp_board", {}).items()}
    truth: npt.ArrayLike | None
    if request.images is None and request.collect is not None:  # a hardware rig: the robot moves the board
        recording = request.collect()
        truth = recording.truth.T_cam_base if recording.truth is not None else None
    elif request.images is not None:
        recording = Recording.load(request.images)
        truth = recording.truth.T_cam_base if recording.truth is not None else None
    else:
        if camera.dist.size and np.any(camera.dist != 0):
            raise ValueError("--camera-model: has lens distortion, which the simulated rig cannot render; use --images")
        if request.poses < 1:
            raise ValueError(f"--poses: expected a number of board poses >= 1, got {request.poses}")
        log(f"rendering {request.poses} held-out poses per arm on the simulated rig (seed {request.seed})")
        recording = record_sim(
            rig,
            request.arm,
            board=ChArUcoBoard.from_yaml(DEFAULT_BOARD),
            poses=request.poses,
            seed=request.seed,
            resolution=camera.width,
            log=log,
            for_calibration=False,
        )
        truth = rig.head_camera_model.T_cam_base
    result = check_views(
        recording.views, camera, rig, truth_T_cam_base=truth, board=recording.board, T_tcp_board=mounts
    )
    checked = result.to_dict()
    summary: dict[str, Any] = {"camera_model": str(model_path) if model_path else None, "views": len(recording.views)}
    summary |= checked
    for line in result.lines():
        log(line)
    _write(request.out, result.overlays, summary, log)
    failure = None
    if request.max_px is not None:
        worst = [
            v
            for entry in checked["arms"].values()
            for k, v in entry.items()
            if k in ("gripper_err_max_px", "board_reproj_rms_px_at_rig_size")
        ]
        if any(v > request.max_px for v in worst):
            failure = f"an error exceeds --max-px {request.max_px}"
    return CheckOutcome(summary, failure)


def _wrist(request: CheckRequest, log: Log) -> CheckOutcome:
    """A wrist camera: FK-predicted board corners on held-out views of the table board."""
    rig, name = request.rig, request.camera
    if rig.hardware is not None and request.images is None:
        raise ValueError(
            f"--camera {name}: a robot-driven wrist-camera check on a hardware rig is not supported yet; "
            "pass a recorded folder with --images"
        )
    arm = wrist_arm(rig, name)  # a one-line error listing the rig's cameras for an unknown name
    rig_size = (rig.image_size.width, rig.image_size.height)
    file = rig.wrist_cameras[name].file
    model_path = request.camera_model or (Path(file) if file is not None else None)
    camera = CameraModel.from_yaml(model_path) if model_path is not None else None
    if camera is None:
        log(
            f"note: {name} has no file: in the rig config {request.rig_path} (wrist_cameras.{name}.file); checking its "
            "designed mount (pose_in_tcp, fovy_deg)"
        )
    board = ChArUcoBoard.from_yaml(DEFAULT_BOARD)
    if request.images is not None:
        recording, camera, T_rig_board = _recorded_wrist_views(request, arm, camera, model_path, log)
        source = str(request.images)
    else:
        if camera is None:
            camera = sim_wrist_camera(rig, name, 1024)
        if camera.dist.size and np.any(camera.dist != 0):
            raise ValueError(
                f"{name}: the camera model has lens distortion, which the simulated rig cannot render; use --images"
            )
        if request.poses < 1:
            raise ValueError(f"--poses: expected a number of camera poses >= 1, got {request.poses}")
        log(f"rendering {request.poses} held-out {name} poses on the simulated rig ({camera.width} px wide)")
        recording, T_rig_board = record_wrist_check_sim(
            rig, name, board=board, poses=request.poses, seed=request.seed, resolution=camera.width, log=log
        )
        source = "simulated rig"
    result = check_wrist_views(
        recording.views, camera, recording.board, rig.kinematics, arm, T_rig_board, rig_size=rig_size, name=name
    )
    checked = result.to_dict()
    summary: dict[str, Any] = {
        "camera_model": str(model_path) if model_path else None,
        "designed_mount": model_path is None,
        "source": source,
        "T_rig_board": np.asarray(T_rig_board).tolist(),
        **checked,
    }
    for line in result.lines():
        log(line)
    _write(request.out, result.overlays, summary, log)
    failure = None
    if request.max_px is not None:
        worst = checked.get("worst_view_rms_px_at_rig_size")
        if worst is None or worst > request.max_px:
            what = "no view showed the board" if worst is None else f"a view's corner RMS {worst:.4f} px at rig size"
            failure = f"{what} (--max-px {request.max_px})"
    return CheckOutcome(summary, failure)


def _recorded_wrist_views(
    request: CheckRequest, arm: str, camera: CameraModel | None, model_path: Path | None, log: Log
) -> tuple[Recording, CameraModel, FloatArray]:
    """A recorded folder's views of ``arm``, the camera under test at their resolution and the board pose."""
    assert request.images is not None
    rig, name = request.rig, request.camera
    recording = Recording.load(request.images)
    sizes = {v.image_size for v in recording.views if v.arm == arm}
    if len(sizes) != 1:
        raise ValueError(f"--images {request.images}: expected {arm}-arm views of one image size, got {sorted(sizes)}")
    (w, h) = sizes.pop()
    if camera is None:
        design = sim_wrist_camera(rig, name, w)  # the designed pinhole and mount
        intr = recording.camera if recording.camera is not None else design
        camera = intr.with_pose(design.T_cam_base)
    elif (camera.width, camera.height) != (w, h):
        if abs(camera.width / camera.height - w / h) > 1e-6:
            raise ValueError(
                f"--images {request.images}: images are {w}x{h} but the camera model is {camera.width}x"
                f"{camera.height} (another aspect ratio); calibrate at the images' resolution"
            )
        camera = camera.resized(w, h)
    report_path = request.report or _beside(model_path)
    truth = WristTruth.from_extra(recording.extra)
    if report_path is not None:
        doc = json.loads(Path(report_path).read_text(encoding="utf-8"))
        if "T_rig_board" not in doc:
            raise ValueError(f"--report {report_path}: no T_rig_board (expected a wrist calibration report)")
        T_rig_board = np.asarray(doc["T_rig_board"], dtype=np.float64).reshape(4, 4)
        board_source = f"the calibration report {report_path}"
    elif truth is not None and truth.camera == name:
        T_rig_board = truth.T_rig_board
        board_source = "the simulator's table board (recorded truth)"
    else:
        raise ValueError(
            f"--report: needed, the calibration JSON holding the board pose T_rig_board (the board must lie "
            f"where it lay for the calibration); none beside {model_path or 'the camera model'}"
        )
    log(f"{len(recording.for_arm(arm))} recorded {arm}-arm views in {request.images}; board pose from {board_source}")
    return recording, camera, T_rig_board
