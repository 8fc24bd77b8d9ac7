"""``pilworld calibrate board|intrinsics|handeye|check``: print a board; calibrate the head camera; check it.

``board`` writes a PNG (at ``--dpi``) and a true-scale vector PDF of a ``configs/board/*.yaml`` board.
``intrinsics`` detects the board in every image of a folder (correcting a legacy-pattern mismatch with a
warning), calibrates, prints per-view errors, parameter σ and 95 % intervals, image coverage and the
held-out error, and writes a ``pilworld.camera_model/v1`` YAML (``T_cam_base`` is the identity until the
hand-eye calibration fills it in).

``handeye`` calibrates the head camera's ``T_cam_base`` (eye-to-hand, the board held by a gripper), or with
``--camera cam_left_wrist`` a wrist camera's ``T_cam_tcp`` (eye-in-hand, the board flat on the table, the
camera's arm moving; the YAML goes to ``wrist_cameras.<name>.file``), from a recorded folder
(``--from DIR``: ``NNN.png`` + ``poses.json``) or, without one, on the simulated rig (pose planner, robot
moves, renders at ``--resolution``; ``--save DIR`` keeps the folder). It writes the camera model YAML that
a rig's ``head_camera.file`` points at, and a JSON report beside it (per-arm residuals, rotation span,
closed-form and OpenCV cross-checks, the two arms' disagreement, and for a simulated rig the true errors).
Degenerate motion exits with ``pilworld: error: hand-eye: degenerate motion: <arm>: <cause>``.

``check`` projects the FK gripper points (and, with the hand-eye report, the board corners) on held-out
views (``--images DIR`` or new simulated poses), prints the pixel error per arm and writes overlays. With
``--camera cam_left_wrist`` it checks a wrist camera eye-in-hand: the board corners FK · ``T_tcp_cam`` ·
``T_rig_board`` predicts against the detected ones, per view (``pilworld.calibration.check``).
See docs/calibration.md. Live capture from a real camera (``--camera SOURCE``) is not implemented yet.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
import warnings
from collections.abc import Callable
from pathlib import Path
from typing import TYPE_CHECKING, Any

import cv2
import numpy as np

from calib.board import ChArUcoBoard
from calib.camera_model import CameraModel
from calib.detect import BoardDetector, Detection
from calib.handeye import DegenerateMotionError
from calib.intrinsics import IntrinsicsOptions, IntrinsicsResult, calibrate_intrinsics
from calib.pdf import page_size_points
from pilworld.config.rig import RigConfig
from pilworld.types import HEAD_VIEW

if TYPE_CHECKING:
    from pilworld.calibration.recording import Recording

IMAGE_SUFFIXES = (".png", ".jpg", ".jpeg", ".bmp", ".tif", ".tiff")
DEFAULT_BOARD_FILE = Path(__file__).resolve().parents[2] / "configs" / "board" / "charuco_7x5_a4.yaml"


def register(sub: Any) -> None:
    p: argparse.ArgumentParser = sub.add_parser(
        "calibrate", help="camera calibration: board, intrinsics, handeye, check"
    )
    cmds = p.add_subparsers(dest="calibrate_command", metavar="COMMAND")
    cmds.required = True

    b = cmds.add_parser("board", help="write a printable ChArUco board (PNG and true-scale PDF)")
    b.add_argument("--config", type=Path, required=True, help="board config, e.g. configs/board/charuco_7x5_a4.yaml")
    b.add_argument("--out", type=Path, required=True, help="output folder (created)")
    b.add_argument("--dpi", type=float, default=300.0, help="PNG resolution in dots per inch (default 300)")
    b.add_argument("--json", action="store_true", help="print a JSON summary as the last line")
    b.set_defaults(handler=_board)

    i = cmds.add_parser(
        "intrinsics", help="calibrate K and distortion from ChArUco images, or live from a hardware rig's camera"
    )
    src = i.add_mutually_exclusive_group(required=True)
    src.add_argument("--images", type=Path, help=f"folder of images ({', '.join(IMAGE_SUFFIXES)})")
    src.add_argument(
        "--live",
        action="store_true",
        help="grab frames from --camera of the hardware rig --rig while the board is moved in front of it",
    )
    i.add_argument("--board", type=Path, default=DEFAULT_BOARD_FILE, help="board config (default: the A4 7x5 board)")
    i.add_argument("--out", type=Path, required=True, help="camera model YAML to write")
    i.add_argument("--name", default=None, help="camera name stored in the YAML (default: --camera, or cam_high)")
    live = i.add_argument_group("live capture (--live)")
    live.add_argument("--rig", type=Path, help="hardware rig config (e.g. configs/rig/fake_dual_ur5e.yaml)")
    live.add_argument("--camera", default="cam_high", help="the rig's camera to calibrate (default cam_high)")
    live.add_argument("--save", type=Path, help="folder for the kept frames (default: --out's name + _views)")
    live.add_argument("--resume", action="store_true", help="continue from the frames already in --save")
    live.add_argument("--preview", type=Path, help="PNG refreshed with the latest frame, its corners and the coverage")
    live.add_argument("--coverage", type=float, default=0.8, help="target image coverage (default 0.8)")
    live.add_argument("--views", type=int, default=20, help="target number of views (default 20)")
    live.add_argument("--max-views", type=int, default=60, help="stop at this many views (default 60)")
    live.add_argument("--rms", type=float, default=0.5, help="target running RMS in px (default 0.5)")
    live.add_argument("--pp-sigma", type=float, default=0.6, help="target σ of the principal point in px (default 0.6)")
    live.add_argument("--max-seconds", type=float, default=900.0, help="time limit in s (default 900)")
    live.add_argument("--hold", type=float, default=0.6, help="fake rig: seconds the simulated person holds each pose")
    i.add_argument(
        "--dist-coeffs", type=int, default=5, choices=(4, 5, 8), help="distortion model: 4, 5 (default) or 8"
    )
    i.add_argument("--held-out", type=float, default=0.2, help="fraction of views held out (default 0.2; 0 = off)")
    i.add_argument("--seed", type=int, default=0, help="seed choosing the held-out views (default 0)")
    i.add_argument("--no-outlier-rejection", action="store_true", help="keep every view")
    i.add_argument("--json", action="store_true", help="print the full report as one JSON object on the last line")
    i.set_defaults(handler=_intrinsics)

    h = cmds.add_parser(
        "handeye",
        help="hand-eye: the head camera (eye-to-hand, board held by a gripper) or a wrist camera (eye-in-hand, "
        "board fixed on the table)",
    )
    h.add_argument("--rig", type=Path, required=True, help="rig config, e.g. configs/rig/sim_dual_ur5e.yaml")
    h.add_argument(
        "--camera",
        default=HEAD_VIEW,
        help=f"camera to calibrate (default {HEAD_VIEW}, the head camera); a wrist camera, e.g. cam_left_wrist, "
        "is calibrated eye-in-hand with the arm that carries it",
    )
    h.add_argument(
        "--arm",
        choices=("left", "right", "both"),
        default=None,
        help="head camera: arm holding the board (default left)",
    )
    h.add_argument(
        "--out",
        type=Path,
        required=True,
        help="camera model YAML to write (head_camera.file or wrist_cameras.<name>.file)",
    )
    h.add_argument(
        "--write-rig",
        type=Path,
        help="wrist camera: also write a copy of the rig config whose wrist_cameras.<name>.file points at --out",
    )
    h.add_argument("--report", type=Path, help="JSON report to write (default: --out with suffix .json)")
    h.add_argument(
        "--from", dest="from_dir", type=Path, help="recorded folder (NNN.png + poses.json); default: the simulated rig"
    )
    h.add_argument(
        "--camera-model", type=Path, help="intrinsics YAML at the image resolution (default: the folder's camera.yaml)"
    )
    h.add_argument("--board", type=Path, help="board config (default: the folder's, or configs/board/charuco_7x5_a4)")
    h.add_argument(
        "--save",
        type=Path,
        help="save the collected views to this folder (hardware rig: always saved, default --out's name + _views)",
    )
    h.add_argument("--poses", type=int, default=20, help="board poses per arm (default 20)")
    h.add_argument("--seed", type=int, default=0, help="pose planner seed (default 0)")
    h.add_argument("--resolution", type=int, default=1024, help="simulated rig: image width (default 1024)")
    _robot_arguments(h)
    h.add_argument("--json", action="store_true", help="print the report as one JSON object on the last line")
    h.set_defaults(handler=_handeye)

    c = cmds.add_parser(
        "check",
        help="held-out views: the head camera's FK-projected gripper points per arm, or a wrist camera's board "
        "corners (--camera NAME)",
    )
    c.add_argument("--rig", type=Path, required=True, help="rig config")
    c.add_argument(
        "--camera",
        default=HEAD_VIEW,
        help=f"camera to check (default {HEAD_VIEW}); a wrist camera, e.g. cam_left_wrist, is checked eye-in-hand: "
        "the board fixed on the table, its arm moving, the rig's wrist_cameras.<name>.file under test",
    )
    c.add_argument(
        "--camera-model",
        type=Path,
        help="calibrated camera YAML (default: the rig's head_camera.file or wrist_cameras.<name>.file, else design)",
    )
    c.add_argument(
        "--handeye-report", type=Path, help="hand-eye JSON report for the board check (default: beside the model)"
    )
    c.add_argument(
        "--report",
        type=Path,
        help="calibration JSON report: for a wrist camera on a recorded folder, holds the board pose T_rig_board "
        "(default: beside the camera model); for the head camera, the same as --handeye-report",
    )
    source = c.add_mutually_exclusive_group()
    source.add_argument("--images", type=Path, help="recorded folder (NNN.png + poses.json)")
    source.add_argument("--sim", action="store_true", help="new held-out poses on the simulated rig (the default)")
    c.add_argument("--arm", choices=("left", "right", "both"), default="both", help="arms to move (default both)")
    c.add_argument("--poses", type=int, default=6, help="held-out poses per arm (default 6)")
    c.add_argument(
        "--seed",
        type=int,
        default=1,
        help="simulated rig: planner seed (default 1, not handeye's 0); a wrist camera plans with seed + 1000",
    )
    c.add_argument("--out", type=Path, help="folder for overlay PNGs and check.json")
    c.add_argument(
        "--max-px",
        type=float,
        help="exit 1 if an error at rig size exceeds it (head: gripper max or board RMS per arm; wrist: the worst "
        "view's corner RMS)",
    )
    c.add_argument("--json", action="store_true", help="print the result as one JSON object on the last line")
    c.add_argument("--save", type=Path, help="hardware rig: folder for the held-out views (default --out/views)")
    _robot_arguments(c)
    c.set_defaults(handler=_check)


def _robot_arguments(p: argparse.ArgumentParser) -> None:
    """What a command that moves a hardware rig's arm takes (a rig with a ``hardware:`` section)."""
    g = p.add_argument_group("hardware rig (a rig file with a hardware: section moves the real arms)")
    g.add_argument("--yes", action="store_true", help="confirm the printed plan in advance (else asked at a terminal)")
    g.add_argument("--resume", action="store_true", help="continue an interrupted collection in --save")
    g.add_argument("--speed", type=float, default=0.5, help="top joint speed of the moves in rad/s (default 0.5)")


def _board(args: argparse.Namespace) -> int:
    board = ChArUcoBoard.from_yaml(args.config)
    args.out.mkdir(parents=True, exist_ok=True)
    png, pdf = args.out / f"{board.name}.png", args.out / f"{board.name}.pdf"
    width_px, height_px = board.write_png(png, dpi=args.dpi)
    w_pt, h_pt = board.write_pdf(pdf)
    w_m, h_m = board.page_size_m
    print(
        f"wrote {pdf} ({w_m * 1e3:.1f} x {h_m * 1e3:.1f} mm page = {w_pt:.2f} x {h_pt:.2f} pt) and {png} "
        f"({width_px}x{height_px} px at {args.dpi:g} dpi). Print the PDF at 100 % / actual size (not 'fit to "
        f"page') and check that a square measures {board.square_length_m * 1e3:.2f} mm."
    )
    if args.json:
        summary = {
            "pdf": str(pdf),
            "png": str(png),
            "page_size_mm": [w_m * 1e3, h_m * 1e3],
            "page_size_pt": list(page_size_points(board.page_size_m)),
            "png_size_px": [width_px, height_px],
            "dpi": args.dpi,
            "corners": board.n_corners,
        }
        print(json.dumps(summary))
    return 0


def _detect_folder(folder: Path, board: ChArUcoBoard) -> tuple[list[Detection], list[str]]:
    if not folder.is_dir():
        raise FileNotFoundError(f"--images: not a folder: {folder}")
    files = sorted(p for p in folder.iterdir() if p.suffix.lower() in IMAGE_SUFFIXES)
    if not files:
        raise ValueError(f"--images: no images ({', '.join(IMAGE_SUFFIXES)}) in {folder}")
    detector = BoardDetector(board)
    detections, messages = [], []
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        for path in files:
            image = cv2.imread(str(path), cv2.IMREAD_GRAYSCALE)
            if image is None:
                raise ValueError(f"--images: cannot read {path} as an image")
            detections.append(detector.detect(np.asarray(image, dtype=np.uint8), name=path.name))
    messages = [str(w.message) for w in caught]
    return detections, messages


def _format_report(result: IntrinsicsResult) -> str:
    lines = [f"{'view':<28} {'corners':>7}  {'status':<16} {'rms px':>7}"]
    for v in result.views:
        rms = f"{v.rms_px:7.3f}" if v.rms_px is not None else "      -"
        lines.append(f"{v.name:<28} {v.n_corners:>7}  {v.status:<16} {rms}")
    held = (
        f"{result.held_out_rms_px:.3f} px over {len(result.held_out_views)} held-out view(s)"
        if result.held_out_rms_px is not None
        else "n/a (too few views to hold any out)"
    )
    lines.append(f"RMS {result.rms_px:.3f} px over {result.n_used} used views; held-out RMS {held}")
    for name, sigma in result.std.items():
        lo, hi = result.intervals95[name]
        lines.append(f"  {name:<3} = {result.value(name): .6g}  σ {sigma:.3g}  95 % [{lo:.6g}, {hi:.6g}]")
    rows, cols = result.coverage_grid.shape
    lines.append(f"coverage: {result.coverage:.0%} of a {cols}x{rows} grid has corners (aim for > 70 %)")
    lines.extend("  " + " ".join("#" if c else "." for c in row) for row in result.coverage_grid)
    return "\n".join(lines)


def _intrinsics(args: argparse.Namespace) -> int:
    if not 0.0 <= args.held_out < 1.0:
        raise ValueError(f"--held-out: expected a fraction in [0, 1), got {args.held_out}")
    if args.live:
        from pilworld.cli.calibrate_rig import intrinsics_live

        if args.rig is None:
            raise ValueError("--live: needs --rig, the hardware rig whose --camera to calibrate")
        return intrinsics_live(args, lambda folder, camera: _solve_intrinsics(args, folder, args.name or camera))
    _, report = _solve_intrinsics(args, args.images, args.name or "cam_high")
    if args.json:
        print(json.dumps(report))
    return 0


def _solve_intrinsics(args: argparse.Namespace, folder: Path, name: str) -> tuple[CameraModel, dict[str, Any]]:
    """Detect, calibrate, print the report and write ``--out``: the solve of a folder of images."""
    board = ChArUcoBoard.from_yaml(args.board)
    detections, messages = _detect_folder(folder, board)
    for message in messages:
        print(f"pilworld: warning: {message}")
    options = IntrinsicsOptions(
        dist_coeffs=args.dist_coeffs,
        held_out_fraction=args.held_out,
        seed=args.seed,
        outlier_k=float("inf") if args.no_outlier_rejection else IntrinsicsOptions.outlier_k,
    )
    result = calibrate_intrinsics(detections, options, name=name)
    args.out.parent.mkdir(parents=True, exist_ok=True)
    result.camera.to_yaml(args.out)
    print(_format_report(result))
    print(f"wrote {args.out}")
    return result.camera, {"out": str(args.out), "warnings": messages, **result.to_dict()}


# ---------------------------------------------------------------------- handeye


def _recording(
    args: argparse.Namespace, poses_noun: str, collecting: str, record: Callable[[], Recording]
) -> tuple[Recording, str]:
    """The views to solve: the ``--from`` folder, or a new simulated recording (saved with ``--save``)."""
    from pilworld.calibration.recording import Recording

    if args.from_dir is not None:
        recording = Recording.load(args.from_dir)
        print(f"{len(recording.views)} recorded views in {args.from_dir}")
        return recording, str(args.from_dir)
    if args.poses < 1:
        raise ValueError(f"--poses: expected a number of {poses_noun} >= 1, got {args.poses}")
    print(collecting)
    try:
        recording = record()
    except DegenerateMotionError as exc:
        raise DegenerateMotionError(f"hand-eye: degenerate motion: {exc}") from None
    if args.save is not None:
        print(f"saved the views to {recording.save(args.save).parent}")
    return recording, "simulated rig"


def _handeye(args: argparse.Namespace) -> int:
    # Imported here: the simulator (MuJoCo, GL) is only needed by these two commands.
    from pilworld.calibration.sim_handeye import DEFAULT_BOARD, arms_for, held_out_states, record_sim
    from pilworld.calibration.sim_truth import truth_errors
    from pilworld.calibration.solve_arms import solve_recording

    start = time.perf_counter()
    rig = RigConfig.load(args.rig)
    if args.camera != HEAD_VIEW:
        if rig.hardware is not None and args.from_dir is None:
            raise ValueError(
                f"--camera {args.camera}: robot-driven wrist-camera calibration on a hardware rig is not supported "
                "yet; record the folder (docs/calibration.md) and pass --from"
            )
        return _handeye_wrist(args, rig, start)
    if args.write_rig is not None:
        raise ValueError("--write-rig: only for a wrist camera (--camera NAME); set head_camera.file by hand")
    args.arm = args.arm or "left"
    arms = arms_for(args.arm)
    if rig.hardware is not None and args.from_dir is None:
        # A hardware rig: the robot moves the board through the planned poses (calibrate_rig), then the
        # recorded folder is solved as any --from folder is.
        from pilworld.cli.calibrate_rig import collect_views_on_rig

        args.board_file = args.board or DEFAULT_BOARD
        folder = args.save or args.out.with_name(args.out.stem + "_views")
        if args.poses < 3:
            raise ValueError(f"--poses: a hand-eye calibration needs at least 3 board poses per arm, got {args.poses}")
        collect_views_on_rig(args, "handeye", folder, arms, args.seed, for_calibration=True)
        args.from_dir, args.save = folder, None
    board = ChArUcoBoard.from_yaml(args.board) if args.board is not None else None
    recording, source = _recording(
        args,
        "board poses",
        f"collecting board views on the simulated rig {rig.name!r} ({args.resolution} px wide)",
        lambda: record_sim(
            rig,
            args.arm,
            board=board or ChArUcoBoard.from_yaml(DEFAULT_BOARD),
            poses=args.poses,
            seed=args.seed,
            resolution=args.resolution,
            log=print,
        ),
    )
    board = board or recording.board
    missing = [a for a in arms if not recording.for_arm(a)]
    if missing:
        raise ValueError(f"--arm {args.arm}: the recording has no views with the {' or '.join(missing)} arm")
    if args.camera_model is not None:
        camera = CameraModel.from_yaml(args.camera_model)
    elif recording.camera is not None:
        camera = recording.camera
    else:
        raise ValueError(
            f"--camera-model: needed, since {args.from_dir} has no camera.yaml (calibrate the intrinsics at the "
            "resolution of the images with `pilworld calibrate intrinsics` first)"
        )
    try:
        outcome = solve_recording(recording.views, camera, board, rig.kinematics, args.arm)
    except DegenerateMotionError as exc:
        raise DegenerateMotionError(f"hand-eye: degenerate motion: {exc}") from None
    args.out.parent.mkdir(parents=True, exist_ok=True)
    outcome.camera.to_yaml(args.out)
    report: dict[str, Any] = {
        "format": "pilworld.handeye_report/v1",
        "rig": rig.name,
        "arm": args.arm,
        "source": source,
        "camera_model": str(args.out),
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
        print(_arm_line(name, result.to_dict()))
    if outcome.both is not None:
        b = outcome.both
        print(
            f"both arms: the two estimates of T_cam_base disagree by {b.disagreement_mm:.3f} mm and "
            f"{b.disagreement_deg:.4f}°; joint refinement over both: residual RMS {b.rms_px:.3f} px"
        )
    if recording.truth is not None:
        truth = truth_errors(rig, outcome, recording.truth, held_out_states(rig, arms, board, args.seed))
        report["truth"] = truth
        w, h = truth["gripper_image_size"]
        print(
            f"vs the simulator's truth: T_cam_base off by {truth['translation_err_mm']:.3f} mm and "
            f"{truth['rotation_err_deg']:.4f}°; held-out gripper points off by max {truth['gripper_reproj_err_px']:.3f}"
            f" px (mean {truth['gripper_reproj_mean_px']:.3f} px) at {w}x{h}"
        )
    report["seconds"] = time.perf_counter() - start
    report_path = args.report if args.report is not None else args.out.with_suffix(".json")
    report_path.parent.mkdir(parents=True, exist_ok=True)
    report_path.write_text(json.dumps(report, indent=1) + "\n", encoding="utf-8")
    print(f"wrote {args.out} and {report_path}")
    if args.json:
        print(json.dumps(report))
    return 0


def _handeye_wrist(args: argparse.Namespace, rig: RigConfig, start: float) -> int:
    """``handeye --camera <wrist camera>``: eye-in-hand, the board fixed on the table, the camera's arm moving."""
    from pilworld.calibration.sim_cameras import wrist_arm
    from pilworld.calibration.sim_handeye import DEFAULT_BOARD, record_sim_wrist
    from pilworld.calibration.sim_truth import WristTruth, wrist_truth_errors
    from pilworld.calibration.solve import calibrate_wrist

    name = args.camera
    arm = wrist_arm(rig, name)  # a one-line error listing the rig's cameras for an unknown name
    if args.arm is not None and args.arm != arm:
        raise ValueError(f"--arm {args.arm}: {name} is carried by the {arm} arm (rig config); drop --arm")
    board = ChArUcoBoard.from_yaml(args.board) if args.board is not None else None
    recording, source = _recording(
        args,
        "camera poses",
        f"collecting {name} views of a board on the table of the simulated rig {rig.name!r} "
        f"({args.resolution} px wide)",
        lambda: record_sim_wrist(
            rig,
            name,
            board=board or ChArUcoBoard.from_yaml(DEFAULT_BOARD),
            poses=args.poses,
            seed=args.seed,
            resolution=args.resolution,
            log=print,
        ),
    )
    board = board or recording.board
    if args.camera_model is not None:
        intrinsics = CameraModel.from_yaml(args.camera_model)
    elif recording.camera is not None:
        intrinsics = recording.camera
    else:
        raise ValueError(
            f"--camera-model: needed, since {args.from_dir} has no camera.yaml (calibrate {name}'s intrinsics at the "
            "resolution of the images with `pilworld calibrate intrinsics --name {name}` first)"
        )
    try:
        result = calibrate_wrist(recording.views, intrinsics, board, rig.kinematics, arm, name)
    except DegenerateMotionError as exc:
        raise DegenerateMotionError(f"hand-eye: degenerate motion: {exc}") from None
    args.out.parent.mkdir(parents=True, exist_ok=True)
    result.camera_model().to_yaml(args.out)
    d = result.to_dict()
    report: dict[str, Any] = {
        "format": "pilworld.handeye_report/v1",
        "calibration": "eye_in_hand",
        "rig": rig.name,
        "camera": name,
        "arm": arm,
        "source": source,
        "camera_model": str(args.out),
        "image_size": [intrinsics.width, intrinsics.height],
        "board": board.name,
        **{k: v for k, v in d.items() if k not in ("camera", "arm")},
    }
    u = d["uncertainty"]
    skipped = f", {len(d['skipped'])} skipped" if d["skipped"] else ""
    closed = ", ".join(f"{m} {v['rms_px']:.3f} px" for m, v in d["closed_form"].items())
    print(
        f"{name} ({arm} arm): {d['poses']} poses{skipped}, rotation span {d['rotation_span_deg']:.1f}°, axis spread "
        f"{d['axis_spread']:.2f}; closed forms {closed}; refined residual RMS {d['residual_rms_px']:.3f} px; "
        f"σ {u['sigma_translation_mm']:.3f} mm, {u['sigma_rotation_deg']:.4f}°"
    )
    truth = WristTruth.from_extra(recording.extra)
    if truth is not None and truth.camera == name:
        errors = wrist_truth_errors(rig, result, truth)
        report["truth"] = errors
        w, h = errors["board_reproj_image_size"]
        print(
            f"vs the simulator's truth: T_tcp_cam off by {errors['translation_err_mm']:.3f} mm and "
            f"{errors['rotation_err_deg']:.4f}°; board corners drawn off by max {errors['board_reproj_err_px']:.4f} px "
            f"at {w}x{h}"
        )
    report["seconds"] = time.perf_counter() - start
    report_path = args.report if args.report is not None else args.out.with_suffix(".json")
    report_path.parent.mkdir(parents=True, exist_ok=True)
    report_path.write_text(json.dumps(report, indent=1) + "\n", encoding="utf-8")
    print(f"wrote {args.out} and {report_path}")
    if args.write_rig is not None:
        _write_rig(args.rig, args.write_rig, name, args.out)
        report["rig_written"] = str(args.write_rig)
        print(f"wrote {args.write_rig}: the rig config with wrist_cameras.{name}.file pointing at {args.out}")
    else:
        print(f"to use it, set in the rig config {args.rig}:  wrist_cameras: {{{name}: {{file: {args.out}}}}}")
    if args.json:
        print(json.dumps(report))
    return 0


def _write_rig(rig_path: Path, out: Path, camera: str, model: Path) -> None:
    """A copy of the rig YAML with ``wrist_cameras.<camera>.file`` = ``model``; other camera files re-based."""
    import os

    import yaml

    doc = yaml.safe_load(rig_path.read_text(encoding="utf-8"))
    src, dst = rig_path.resolve().parent, out.resolve().parent

    def rebase(value: str) -> str:
        path = Path(value).expanduser()
        return value if path.is_absolute() else os.path.relpath(src / path, dst)

    head = doc.get("head_camera") or {}
    if head.get("file"):
        head["file"] = rebase(str(head["file"]))
    for cam_name, cam in (doc.get("wrist_cameras") or {}).items():
        if cam_name != camera and cam.get("file"):
            cam["file"] = rebase(str(cam["file"]))
    doc["wrist_cameras"][camera]["file"] = os.path.relpath(model.resolve(), dst)
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(
        f"# Written by `pilworld calibrate handeye --camera {camera} --write-rig`: {rig_path} with the calibrated "
        f"{camera}.\n" + yaml.safe_dump(doc, sort_keys=False),
        encoding="utf-8",
    )
    RigConfig.load(out)  # the copy must load (the model file exists, the fields validate)


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


# ---------------------------------------------------------------------- check


def _check(args: argparse.Namespace) -> int:
    from pilworld.calibration.check import check_views
    from pilworld.calibration.recording import Recording
    from pilworld.calibration.sim_cameras import sim_calibration_camera
    from pilworld.calibration.sim_handeye import DEFAULT_BOARD, arms_for, record_sim

    rig = RigConfig.load(args.rig)
    if args.camera != HEAD_VIEW:
        if rig.hardware is not None and args.images is None:
            raise ValueError(
                f"--camera {args.camera}: a robot-driven wrist-camera check on a hardware rig is not supported yet; "
                "pass a recorded folder with --images"
            )
        return _check_wrist(args, rig)
    if args.camera_model is not None:
        camera = CameraModel.from_yaml(args.camera_model)
    elif rig.head_camera.file is not None:
        camera = CameraModel.from_yaml(rig.head_camera.file)
    else:
        camera = sim_calibration_camera(rig, 1024)  # a designed camera: checks the pipeline, not a calibration
    report_path = args.handeye_report or args.report
    model_path = args.camera_model or (Path(rig.head_camera.file) if rig.head_camera.file else None)
    if report_path is None and model_path is not None and model_path.with_suffix(".json").is_file():
        report_path = model_path.with_suffix(".json")
    mounts: dict[str, Any] | None = None
    if report_path is not None:
        doc = json.loads(Path(report_path).read_text(encoding="utf-8"))
        mounts = {a: np.asarray(T, dtype=np.float64) for a, T in doc.get("T_tcp_board", {}).items()}
    if args.images is None and rig.hardware is not None:
        # A hardware rig: the robot moves the board to held-out poses (planner seed --seed, not the
        # calibration's), the views are recorded, then checked as a recorded folder is.
        from pilworld.cli.calibrate_rig import collect_views_on_rig

        if args.poses < 1:
            raise ValueError(f"--poses: expected a number of board poses >= 1, got {args.poses}")
        if args.out is None and args.save is None:
            raise ValueError("--out (or --save): a check on a hardware rig records its held-out views there")
        args.board_file = DEFAULT_BOARD
        folder = args.save or args.out / "views"
        recording = collect_views_on_rig(args, "check", folder, arms_for(args.arm), args.seed, for_calibration=False)
        truth = recording.truth.T_cam_base if recording.truth is not None else None
        if args.camera_model is None and rig.head_camera.file is None:
            raise ValueError(
                "--camera-model: needed on a hardware rig (the calibration to check, as `calibrate handeye` wrote it)"
            )
    elif args.images is not None:
        recording = Recording.load(args.images)
        truth = recording.truth.T_cam_base if recording.truth is not None else None
    else:
        if camera.dist.size and np.any(camera.dist != 0):
            raise ValueError("--camera-model: has lens distortion, which the simulated rig cannot render; use --images")
        if args.poses < 1:
            raise ValueError(f"--poses: expected a number of board poses >= 1, got {args.poses}")
        print(f"rendering {args.poses} held-out poses per arm on the simulated rig (seed {args.seed})")
        recording = record_sim(
            rig,
            args.arm,
            board=ChArUcoBoard.from_yaml(DEFAULT_BOARD),
            poses=args.poses,
            seed=args.seed,
            resolution=camera.width,
            log=print,
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
        print(line)
    if args.out is not None:
        args.out.mkdir(parents=True, exist_ok=True)
        for name, image in result.overlays.items():
            cv2.imwrite(str(args.out / f"check_{Path(name).stem}.png"), cv2.cvtColor(image, cv2.COLOR_RGB2BGR))
        (args.out / "check.json").write_text(json.dumps(summary, indent=1) + "\n", encoding="utf-8")
        print(f"wrote {len(result.overlays)} overlays and check.json to {args.out}")
    if args.json:
        print(json.dumps(summary))
    if args.max_px is not None:
        worst = [
            v
            for entry in checked["arms"].values()
            for k, v in entry.items()
            if k in ("gripper_err_max_px", "board_reproj_rms_px_at_rig_size")
        ]
        if any(v > args.max_px for v in worst):
            print(f"pilworld: check failed: an error exceeds --max-px {args.max_px}", file=sys.stderr)
            return 1
    return 0


def _check_wrist(args: argparse.Namespace, rig: RigConfig) -> int:
    """``check --camera <wrist camera>``: FK-predicted board corners on held-out views of the table board."""
    from pilworld.calibration.check import check_wrist_views
    from pilworld.calibration.recording import Recording
    from pilworld.calibration.sim_cameras import sim_wrist_camera, wrist_arm
    from pilworld.calibration.sim_handeye import DEFAULT_BOARD, record_wrist_check_sim
    from pilworld.calibration.sim_truth import WristTruth

    name = args.camera
    arm = wrist_arm(rig, name)  # a one-line error listing the rig's cameras for an unknown name
    rig_size = (rig.image_size.width, rig.image_size.height)
    file = rig.wrist_cameras[name].file
    model_path = args.camera_model or (Path(file) if file is not None else None)
    camera = CameraModel.from_yaml(model_path) if model_path is not None else None
    if camera is None:
        print(
            f"note: {name} has no file: in the rig config {args.rig} (wrist_cameras.{name}.file); checking its "
            "designed mount (pose_in_tcp, fovy_deg)"
        )
    board = ChArUcoBoard.from_yaml(DEFAULT_BOARD)
    if args.images is not None:
        recording = Recording.load(args.images)
        board = recording.board
        sizes = {v.image_size for v in recording.views if v.arm == arm}
        if len(sizes) != 1:
            raise ValueError(f"--images {args.images}: expected {arm}-arm views of one image size, got {sorted(sizes)}")
        (w, h) = sizes.pop()
        if camera is None:
            design = sim_wrist_camera(rig, name, w)  # the designed pinhole and mount
            intr = recording.camera if recording.camera is not None else design
            camera = intr.with_pose(design.T_cam_base)
        elif (camera.width, camera.height) != (w, h):
            if abs(camera.width / camera.height - w / h) > 1e-6:
                raise ValueError(
                    f"--images {args.images}: images are {w}x{h} but the camera model is {camera.width}x"
                    f"{camera.height} (another aspect ratio); calibrate at the images' resolution"
                )
            camera = camera.resized(w, h)
        report_path = args.report
        if report_path is None and model_path is not None and model_path.with_suffix(".json").is_file():
            report_path = model_path.with_suffix(".json")
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
        source = str(args.images)
        print(
            f"{len(recording.for_arm(arm))} recorded {arm}-arm views in {args.images}; board pose from {board_source}"
        )
    else:
        if camera is None:
            camera = sim_wrist_camera(rig, name, 1024)
        if camera.dist.size and np.any(camera.dist != 0):
            raise ValueError(
                f"{name}: the camera model has lens distortion, which the simulated rig cannot render; use --images"
            )
        if args.poses < 1:
            raise ValueError(f"--poses: expected a number of camera poses >= 1, got {args.poses}")
        print(f"rendering {args.poses} held-out {name} poses on the simulated rig ({camera.width} px wide)")
        recording, T_rig_board = record_wrist_check_sim(
            rig, name, board=board, poses=args.poses, seed=args.seed, resolution=camera.width, log=print
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
        print(line)
    if args.out is not None:
        args.out.mkdir(parents=True, exist_ok=True)
        for view, image in result.overlays.items():
            cv2.imwrite(str(args.out / f"check_{Path(view).stem}.png"), cv2.cvtColor(image, cv2.COLOR_RGB2BGR))
        (args.out / "check.json").write_text(json.dumps(summary, indent=1) + "\n", encoding="utf-8")
        print(f"wrote {len(result.overlays)} overlays and check.json to {args.out}")
    if args.json:
        print(json.dumps(summary))
    if args.max_px is not None:
        worst = checked.get("worst_view_rms_px_at_rig_size")
        if worst is None or worst > args.max_px:
            what = "no view showed the board" if worst is None else f"a view's corner RMS {worst:.4f} px at rig size"
            print(f"pilworld: check failed: {what} (--max-px {args.max_px})", file=sys.stderr)
            return 1
    return 0
