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
``T_rig_board`` predicts against the detected ones, per view.

The hand-eye and check work is done by :mod:`pilworld.calibration.run_handeye` and
:mod:`pilworld.calibration.run_check`; this module parses the flags, calls them and prints.
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


# ---------------------------------------------------------------------- handeye and check


def _handeye(args: argparse.Namespace) -> int:
    # Imported here: the simulator (MuJoCo, GL) is only needed by these two commands.
    from pilworld.calibration.run_handeye import HandEyeRequest, run_handeye

    start = time.perf_counter()
    rig = RigConfig.load(args.rig)
    request = HandEyeRequest(
        rig_path=args.rig,
        rig=rig,
        out=args.out,
        camera=args.camera,
        arm=args.arm,
        report=args.report,
        from_dir=args.from_dir,
        camera_model=args.camera_model,
        board=args.board,
        save=args.save,
        poses=args.poses,
        seed=args.seed,
        resolution=args.resolution,
        write_rig=args.write_rig,
        collect=_handeye_collector(args) if rig.hardware is not None else None,
        started=start,
    )
    report = run_handeye(request, log=print)
    if args.json:
        print(json.dumps(report))
    return 0


def _handeye_collector(args: argparse.Namespace) -> Callable[[tuple[str, ...]], Path]:
    """A hardware rig: the robot moves the board through the planned poses into a folder (calibrate_rig)."""

    def collect(arms: tuple[str, ...]) -> Path:
        from pilworld.calibration.sim_handeye import DEFAULT_BOARD
        from pilworld.cli.calibrate_rig import collect_views_on_rig

        args.board_file = args.board or DEFAULT_BOARD
        folder: Path = args.save or args.out.with_name(args.out.stem + "_views")
        if args.poses < 3:
            raise ValueError(f"--poses: a hand-eye calibration needs at least 3 board poses per arm, got {args.poses}")
        collect_views_on_rig(args, "handeye", folder, arms, args.seed, for_calibration=True)
        return folder

    return collect


def _check(args: argparse.Namespace) -> int:
    from pilworld.calibration.run_check import CheckRequest, run_check

    rig = RigConfig.load(args.rig)
    request = CheckRequest(
        rig_path=args.rig,
        rig=rig,
        camera=args.camera,
        camera_model=args.camera_model,
        handeye_report=args.handeye_report,
        report=args.report,
        images=args.images,
        arm=args.arm,
        poses=args.poses,
        seed=args.seed,
        out=args.out,
        max_px=args.max_px,
        collect=_check_collector(args, rig) if rig.hardware is not None else None,
    )
    outcome = run_check(request, log=print)
    if args.json:
        print(json.dumps(outcome.summary))
    if outcome.failure is not None:
        print(f"pilworld: check failed: {outcome.failure}", file=sys.stderr)
        return 1
    return 0


def _check_collector(args: argparse.Namespace, rig: RigConfig) -> Callable[[], Recording]:
    """A hardware rig: the robot moves the board to held-out poses (planner seed --seed, not the calibration's),
    the views are recorded into a folder and checked as a recorded folder is."""

    def collect() -> Recording:
        from pilworld.calibration.sim_handeye import DEFAULT_BOARD, arms_for
        from pilworld.cli.calibrate_rig import collect_views_on_rig

        if args.poses < 1:
            raise ValueError(f"--poses: expected a number of board poses >= 1, got {args.poses}")
        if args.out is None and args.save is None:
            raise ValueError("--out (or --save): a check on a hardware rig records its held-out views there")
        args.board_file = DEFAULT_BOARD
        folder = args.save or args.out / "views"
        recording: Recording = collect_views_on_rig(
            args, "check", folder, arms_for(args.arm), args.seed, for_calibration=False
        )
        if args.camera_model is None and rig.head_camera.file is None:
            raise ValueError(
                "--camera-model: needed on a hardware rig (the calibration to check, as `calibrate handeye` wrote it)"
            )
        return recording

    return collect
