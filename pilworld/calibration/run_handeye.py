"""``pilworld calibrate handeye`` end to end, for either camera mount: views in, camera model and report out.

The views come from a recorded folder (``NNN.png`` + ``poses.json``), from a hardware rig's robot (the
command's own collector, :attr:`HandEyeRequest.collect`) or, by default, from the simulated rig
(:mod:`.sim_handeye`; kept with ``save``). Then, by the camera (docs/calibration.md, "3. Hand-eye"
and "Wrist cameras (eye-in-hand)"):

* the **head camera** (eye-to-hand) is solved with one arm or both (:func:`.solve_arms.solve_recording`)
  and written as the ``pilworld.camera_model/v1`` a rig's ``head_camera.file`` points at;
* a **wrist camera** (eye-in-hand) is solved with the arm that carries it (:func:`.solve.calibrate_wrist`)
  and written as its ``wrist_cameras.<name>.file`` (``T_cam_base`` is ``T_cam_tcp``), optionally with a
  copy of the rig config pointing at it (:mod:`.rig_file`).

A JSON report goes beside the model (``pilworld.handeye_report/v1``: residuals, rotation span, closed-form
and OpenCV cross-checks, and for a simulated rig the true errors). Degenerate motion is refused with
``hand-eye: degenerate motion: <arm or camera>: <cause>``; nothing is written then.
"""

from __future__ import annotations

import json
import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

from calib.board import ChArUcoBoard
from calib.camera_model import CameraModel
from calib.handeye import DegenerateMotionError
from pilworld.calibration.recording import Recording
from pilworld.calibration.rig_file import write_rig_with_camera
from pilworld.calibration.sim_cameras import wrist_arm
from pilworld.calibration.sim_handeye import DEFAULT_BOARD, arms_for, held_out_states, record_sim, record_sim_wrist
from pilworld.calibration.sim_truth import WristTruth, truth_errors, truth_line, wrist_truth_errors, wrist_truth_line
from pilworld.calibration.solve import calibrate_wrist
from pilworld.calibration.solve_arms import solve_recording
from pilworld.config.rig import RigConfig
from pilworld.types import HEAD_VIEW

__all__ = ["REPORT_FORMAT", "HandEyeRequest", "run_handeye"]

REPORT_FORMAT = "pilworld.handeye_report/v1"
Log = Callable[[str], None]


@dataclass(frozen=True)
class HandEyeRequest:
    """What ``pilworld calibrate handeye`` was asked (its flags, typed)."""

    rig_path: Path
    rig: RigConfig
    out: Path  #: the camera model YAML to write
    camera: str = HEAD_VIEW  #: the head camera, or a wrist camera's name
    arm: str | None = None  #: head camera: left (the default), right or both; a wrist camera: its own arm or None
    report: Path | None = None  #: default: ``out`` with suffix .json
    from_dir: Path | None = None  #: a recorded folder
    camera_model: Path | None = None  #: intrinsics at the images' resolution (default: the folder's camera.yaml)
    board: Path | None = None  #: board config (default: the folder's, or the A4 board)
    save: Path | None = None  #: keep a simulated recording here
    poses: int = 20
    seed: int = 0
    resolution: int = 1024  #: simulated rig: image width
    write_rig: Path | None = None  #: wrist camera: also write a rig config pointing at ``out``
    #: a hardware rig's collector: moves the robot through planned poses for these arms, returns the folder
    collect: Callable[[tuple[str, ...]], Path] | None = None
    started: float = 0.0  #: ``time.perf_counter()`` when the command started (the report's ``seconds``)


def run_handeye(request: HandEyeRequest, log: Log) -> dict[str, Any]:
    """Calibrate, write the camera model and the report, say what was done with ``log``; returns the report."""
    if request.camera != HEAD_VIEW:
        return _wrist(request, log)
    return _head(request, log)


@contextmanager
def _refusing_degenerate_motion() -> Iterator[None]:
    try:
        yield
    except DegenerateMotionError as exc:
        raise DegenerateMotionError(f"hand-eye: degenerate motion: {exc}") from None


def _views(request: HandEyeRequest, arm: str, board: ChArUcoBoard | None, log: Log) -> tuple[Recording, str]:
    """The views to solve and where they came from: the folder, or a new simulated recording (kept with ``save``)."""
    rig, name = request.rig, request.camera
    wrist = name != HEAD_VIEW
    # The head camera records with the arms holding the board, a wrist camera with the arm carrying it.
    record: Callable[..., Recording] = record_sim_wrist if wrist else record_sim
    if request.from_dir is not None:
        recording = Recording.load(request.from_dir)
        log(f"{len(recording.views)} recorded views in {request.from_dir}")
        return recording, str(request.from_dir)
    if request.poses < 1:
        noun = "camera" if wrist else "board"
        raise ValueError(f"--poses: expected a number of {noun} poses >= 1, got {request.poses}")
    what = f"{name} views of a board on the table of" if wrist else "board views on"
    log(f"collecting {what} the simulated rig {rig.name!r} ({request.resolution} px wide)")
    with _refusing_degenerate_motion():
        recording = record(
            rig,
            name if wrist else arm,
            board=board or ChArUcoBoard.from_yaml(DEFAULT_BOARD),
            poses=request.poses,
            seed=request.seed,
            resolution=request.resolution,
            log=log,
        )
    if request.save is not None:
        log(f"saved the views to {recording.save(request.save).parent}")
    return recording, "simulated rig"


def _intrinsics(request: HandEyeRequest, recording: Recording, advice: str) -> CameraModel:
    if request.camera_model is not None:
        return CameraModel.from_yaml(request.camera_model)
    if recording.camera is not None:
        return recording.camera
    raise ValueError(f"--camera-model: needed, since {request.from_dir} has no camera.yaml ({advice})")


def _board(request: HandEyeRequest) -> ChArUcoBoard | None:
    return ChArUcoBoard.from_yaml(request.board) if request.board is not None else None


def _write_report(request: HandEyeRequest, report: dict[str, Any], log: Log) -> None:
    report["seconds"] = time.perf_counter() - request.started
    report_path = request.report if request.report is not None else request.out.with_suffix(".json")
    report_path.parent.mkdir(parents=True, exist_ok=True)
    report_path.write_text(json.dumps(report, indent=1) + "\n", encoding="utf-8")
    log(f"wrote {request.out} and {report_path}")


def _arm_line(name: str, d: dict[str, Any]) -> str:
    closed = ", ".join(f"{m} {v['rms_px']:.3f} px" for m, v in d["closed_form"].items())
    cv = d["opencv"]
    cv_text = (
        "OpenCV " + ", ".join(f"{m} {v['diff_mm']:.2f} mm/{v['diff_deg']:.3f}°" for m, v in cv.items())
        if cv
        else "OpenCV cross-check unavailable (this cv2 has no calibrateHandEye)"
    )
    skipped = f", {len(d['skipped'])} skipped" if d["skipped"] else ""
    return (
        f"{name:>5} arm: {d['poses']} poses{skipped}, rotation span {d['rotation_span_deg']:.1f}°, axis spread "
        f"{d['axis_spread']:.2f}; closed forms {closed}; refined residual RMS {d['residual_rms_px']:.3f} px; "
        f"{cv_text} from ours"
    )


def _head(request: HandEyeRequest, log: Log) -> dict[str, Any]:
    """The head camera, eye-to-hand: the board held by one arm or both."""
    rig = request.rig
    if request.write_rig is not None:
        raise ValueError("--write-rig: only for a wrist camera (--camera NAME); set head_camera.file by hand")
    arm = request.arm or "left"
    arms = arms_for(arm)
    if request.collect is not None and request.from_dir is None:  # a hardware rig: the robot moves the board
        request = replace(request, from_dir=request.collect(arms), save=None)
    board = _board(request)
    recording, source = _views(request, arm, board, log)
    board = board or recording.board
    missing = [a for a in arms if not recording.for_arm(a)]
    if missing:
        raise ValueError(f"--arm {arm}: the recording has no views with the {' or '.join(missing)} arm")
    camera = _intrinsics(
        request,
        recording,
        "calibrate the intrinsics at the resolution of the images with `pilworld calibrate intrinsics` first",
    )
    with _refusing_degenerate_motion():
        outcome = solve_recording(recording.views, camera, board, rig.kinematics, arm)
    request.out.parent.mkdir(parents=True, exist_ok=True)
    outcome.camera.to_yaml(request.out)
    report: dict[str, Any] = {
        "format": REPORT_FORMAT,
        "rig": rig.name,
        "arm": arm,
        "source": source,
        "camera_model": str(request.out),
        "image_size": [camera.width, camera.height],
        "board": board.name,
        "poses": outcome.poses,
        "rotation_span_deg": outcome.rotation_span_deg,
        "residual_rms_px": outcome.residual_rms_px,
        "arms": {a: r.to_dict() for a, r in outcome.per_arm.items()},
        "T_cam_base": outcome.T_cam_base.tolist(),
        "T_tcp_board": {a: T.tolist() for a, T in outcome.T_tcp_board.items()},
    }
    if outcome.both is not None:
        report["combined"] = outcome.both.to_dict()
    for name, result in outcome.per_arm.items():
        log(_arm_line(name, result.to_dict()))
    if outcome.both is not None:
        b = outcome.both
        log(
            f"both arms: the two estimates of T_cam_base disagree by {b.disagreement_mm:.3f} mm and "
            f"{b.disagreement_deg:.4f}°; joint refinement over both: residual RMS {b.rms_px:.3f} px"
        )
    if recording.truth is not None:
        truth = truth_errors(rig, outcome, recording.truth, held_out_states(rig, arms, board, request.seed))
        report["truth"] = truth
        log(truth_line(truth))
    _write_report(request, report, log)
    return report


def _wrist(request: HandEyeRequest, log: Log) -> dict[str, Any]:
    """A wrist camera, eye-in-hand: the board fixed on the table, the camera's arm moving."""
    rig, name = request.rig, request.camera
    if rig.hardware is not None and request.from_dir is None:
        raise ValueError(
            f"--camera {name}: robot-driven wrist-camera calibration on a hardware rig is not supported "
            "yet; record the folder (docs/calibration.md) and pass --from"
        )
    arm = wrist_arm(rig, name)  # a one-line error listing the rig's cameras for an unknown name
    if request.arm is not None and request.arm != arm:
        raise ValueError(f"--arm {request.arm}: {name} is carried by the {arm} arm (rig config); drop --arm")
    board = _board(request)
    recording, source = _views(request, arm, board, log)
    board = board or recording.board
    advice = (
        f"calibrate {name}'s intrinsics at the resolution of the images with `pilworld calibrate intrinsics "
        f"--name {name}` first"
    )
    intrinsics = _intrinsics(request, recording, advice)
    with _refusing_degenerate_motion():
        result = calibrate_wrist(recording.views, intrinsics, board, rig.kinematics, arm, name)
    request.out.parent.mkdir(parents=True, exist_ok=True)
    result.camera_model().to_yaml(request.out)
    d = result.to_dict()
    report: dict[str, Any] = {
        "format": REPORT_FORMAT,
        "calibration": "eye_in_hand",
        "rig": rig.name,
        "camera": name,
        "arm": arm,
        "source": source,
        "camera_model": str(request.out),
        "image_size": [intrinsics.width, intrinsics.height],
        "board": board.name,
        **{k: v for k, v in d.items() if k not in ("camera", "arm")},
    }
    u = d["uncertainty"]
    skipped = f", {len(d['skipped'])} skipped" if d["skipped"] else ""
    closed = ", ".join(f"{m} {v['rms_px']:.3f} px" for m, v in d["closed_form"].items())
    log(
        f"{name} ({arm} arm): {d['poses']} poses{skipped}, rotation span {d['rotation_span_deg']:.1f}°, axis spread "
        f"{d['axis_spread']:.2f}; closed forms {closed}; refined residual RMS {d['residual_rms_px']:.3f} px; "
        f"σ {u['sigma_translation_mm']:.3f} mm, {u['sigma_rotation_deg']:.4f}°"
    )
    truth = WristTruth.from_extra(recording.extra)
    if truth is not None and truth.camera == name:
        errors = wrist_truth_errors(rig, result, truth)
        report["truth"] = errors
        log(wrist_truth_line(errors))
    _write_report(request, report, log)
    if request.write_rig is not None:
        write_rig_with_camera(request.rig_path, request.write_rig, name, request.out)
        report["rig_written"] = str(request.write_rig)  # after the file: only the printed report says so
        log(f"wrote {request.write_rig}: the rig config with wrist_cameras.{name}.file pointing at {request.out}")
    else:
        log(f"to use it, set in the rig config {request.rig_path}:  wrist_cameras: {{{name}: {{file: {request.out}}}}}")
    return report
