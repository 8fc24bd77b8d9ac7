"""``pilworld calibrate board|intrinsics``: print a ChArUco board; calibrate a camera's intrinsics from images.

``board`` writes a PNG (at ``--dpi``) and a true-scale vector PDF of a ``configs/board/*.yaml`` board.
``intrinsics`` detects the board in every image of a folder (correcting a legacy-pattern mismatch with a
warning), calibrates, prints per-view errors, parameter σ and 95 % intervals, image coverage and the
held-out error, and writes a ``pilworld.camera_model/v1`` YAML (``T_cam_base`` is the identity until the
hand-eye calibration fills it in). Live capture (``--camera SOURCE``), ``handeye`` and ``check`` are not
implemented yet (issue #9).
"""

from __future__ import annotations

import argparse
import json
import warnings
from pathlib import Path
from typing import Any

import cv2
import numpy as np

from calib.board import ChArUcoBoard
from calib.detect import BoardDetector, Detection
from calib.intrinsics import IntrinsicsOptions, IntrinsicsResult, calibrate_intrinsics
from calib.pdf import page_size_points

IMAGE_SUFFIXES = (".png", ".jpg", ".jpeg", ".bmp", ".tif", ".tiff")


def register(sub: Any) -> None:
    p: argparse.ArgumentParser = sub.add_parser("calibrate", help="camera calibration: board, intrinsics")
    cmds = p.add_subparsers(dest="calibrate_command", metavar="COMMAND")
    cmds.required = True

    b = cmds.add_parser("board", help="write a printable ChArUco board (PNG and true-scale PDF)")
    b.add_argument("--config", type=Path, required=True, help="board config, e.g. configs/board/charuco_7x5_a4.yaml")
    b.add_argument("--out", type=Path, required=True, help="output folder (created)")
    b.add_argument("--dpi", type=float, default=300.0, help="PNG resolution in dots per inch (default 300)")
    b.add_argument("--json", action="store_true", help="print a JSON summary as the last line")
    b.set_defaults(handler=_board)

    i = cmds.add_parser("intrinsics", help="calibrate K and distortion from ChArUco images")
    i.add_argument("--images", type=Path, required=True, help=f"folder of images ({', '.join(IMAGE_SUFFIXES)})")
    i.add_argument("--board", type=Path, required=True, help="board config the images show")
    i.add_argument("--out", type=Path, required=True, help="camera model YAML to write")
    i.add_argument("--name", default="cam_high", help="camera name stored in the YAML (default cam_high)")
    i.add_argument(
        "--dist-coeffs", type=int, default=5, choices=(4, 5, 8), help="distortion model: 4, 5 (default) or 8"
    )
    i.add_argument("--held-out", type=float, default=0.2, help="fraction of views held out (default 0.2; 0 = off)")
    i.add_argument("--seed", type=int, default=0, help="seed choosing the held-out views (default 0)")
    i.add_argument("--no-outlier-rejection", action="store_true", help="keep every view")
    i.add_argument("--json", action="store_true", help="print the full report as one JSON object on the last line")
    i.set_defaults(handler=_intrinsics)


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
    board = ChArUcoBoard.from_yaml(args.board)
    detections, messages = _detect_folder(args.images, board)
    for message in messages:
        print(f"pilworld: warning: {message}")
    options = IntrinsicsOptions(
        dist_coeffs=args.dist_coeffs,
        held_out_fraction=args.held_out,
        seed=args.seed,
        outlier_k=float("inf") if args.no_outlier_rejection else IntrinsicsOptions.outlier_k,
    )
    result = calibrate_intrinsics(detections, options, name=args.name)
    args.out.parent.mkdir(parents=True, exist_ok=True)
    result.camera.to_yaml(args.out)
    print(_format_report(result))
    print(f"wrote {args.out}")
    if args.json:
        print(json.dumps({"out": str(args.out), "warnings": messages, **result.to_dict()}))
    return 0
