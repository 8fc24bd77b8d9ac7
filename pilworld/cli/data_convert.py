"""``pilworld data convert SOURCE OUT``: import a LeRobot v2.1/v3.0 or ALOHA HDF5 dataset.

``add_convert_parser`` is attached to the ``pilworld data`` sub-commands; its handler prints a
one-line summary and, with ``--json``, the summary as one JSON object on the last line.
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path
from typing import Any

from pilworld.data.video_codec import VIDEO_MODES

FORMAT_CHOICES = ("auto", "lerobot-v21", "lerobot-v30", "aloha-hdf5")  # = pilworld.data.convert.FORMATS


def add_convert_parser(data_subparsers: Any) -> argparse.ArgumentParser:
    """Add ``convert`` to the sub-parsers of ``pilworld data``; returns the new parser."""
    p: argparse.ArgumentParser = data_subparsers.add_parser(
        "convert",
        help="import a LeRobot v2.1/v3.0 or ALOHA HDF5 dataset",
        description=(
            "Convert SOURCE (a LeRobot v2.0/v2.1/v3.0 folder, a folder of ALOHA episode_*.hdf5 files, or one "
            "such file) into a PiL-World dataset at OUT. Re-running after an interruption continues where "
            "it stopped."
        ),
    )
    p.add_argument("source", type=Path, metavar="SOURCE", help="dataset folder or .hdf5 file")
    p.add_argument("out", type=Path, metavar="OUT", help="output dataset folder (created, or resumed)")
    p.add_argument("--format", dest="fmt", choices=FORMAT_CHOICES, default="auto", help="source format (default auto)")
    p.add_argument("--mapping", type=Path, metavar="MAP.yaml", help="cameras → views, state/action keys, resize, task")
    p.add_argument("--video-mode", choices=VIDEO_MODES, default="h264", help="output video codec (default h264)")
    p.add_argument("--task", metavar="TEXT", help="instruction for episodes without one (required for ALOHA HDF5)")
    p.add_argument(
        "--append",
        action="store_true",
        help="add SOURCE's episodes after those of the sources OUT already holds (OUT/conversion.json lists them); "
        "without it, OUT takes one source: a rerun resumes it, another source is refused",
    )
    p.add_argument("--json", action="store_true", help="print the summary as one JSON object on the last line")
    p.set_defaults(handler=_convert)
    return p


def _convert(args: argparse.Namespace) -> int:
    # Imported here so `pilworld --help` does not load h5py, PyAV and pyarrow.
    from pilworld.data.convert import ConvertMapping, convert, load_mapping

    mapping = load_mapping(args.mapping) if args.mapping is not None else ConvertMapping()
    if args.task is not None:
        mapping = mapping.with_overrides(task=args.task)
    summary = convert(
        args.source,
        args.out,
        mapping,
        video_mode=args.video_mode,
        fmt=args.fmt,
        progress=not args.json,
        append=args.append,
    )
    views = ", ".join(f"{v} {h}x{w}" for v, (h, w) in summary["views"].items())
    print(
        f"convert: {summary['converted']} episodes ({summary['converted_frames']} frames) from {summary['format']} "
        f"{summary['source']} → {summary['out']} [{views}; state {summary['state_dim']}, action "
        f"{summary['action_dim']}, {summary['fps']} fps, {summary['video_mode']}]"
        + (f", {summary['skipped']} already there" if summary["skipped"] else "")
        + f" in {summary['seconds']:.1f} s"
    )
    if args.json:
        print(json.dumps(summary))
    return 0
