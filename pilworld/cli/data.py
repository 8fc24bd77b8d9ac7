"""``pilworld data info|convert``: inspect and import episode datasets (LeRobot v3.0 layout)."""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path
from typing import Any


def register(sub: Any) -> None:
    p: argparse.ArgumentParser = sub.add_parser("data", help="inspect and convert episode datasets")
    data = p.add_subparsers(dest="data_command", metavar="SUBCOMMAND")
    data.required = True

    info = data.add_parser(
        "info", help="episodes, frames, cameras, origins and outcomes of a dataset; exit 1 if files are missing"
    )
    info.add_argument("path", type=Path, help="dataset folder (LeRobot v3.0 layout)")
    info.add_argument("--json", action="store_true", help="print the summary as one JSON object on the last line")
    info.set_defaults(handler=_info)

    verify = data.add_parser(
        "verify",
        help="check every file of every episode against its manifest (size and sha256); exit 1 on damage",
    )
    verify.add_argument("path", type=Path, help="dataset folder, or a paired / imagine run folder (with starts/)")
    verify.add_argument("--json", action="store_true", help="print the report as one JSON object on the last line")
    verify.add_argument(
        "--sizes-only", action="store_true", help="check existence and sizes only (no hashing: the cheap check)"
    )
    verify.add_argument("--no-progress", action="store_true", help="no progress bar")
    verify.set_defaults(handler=_verify)

    from pilworld.cli.data_convert import add_convert_parser

    add_convert_parser(data)


def _info(args: argparse.Namespace) -> int:
    from pilworld.data.info import dataset_info
    from pilworld.data.reader import DamagedDatasetError, DatasetError

    try:
        summary = dataset_info(args.path)
    except DatasetError as err:  # a dataset whose metadata is damaged or missing: exit 1, as documented
        if not isinstance(err, DamagedDatasetError) and not _dataset_parts(args.path):
            raise  # not a dataset at all: bad input, exit 2
        print(f"pilworld: error: {' '.join(str(err).split())}", file=sys.stderr)
        return 1
    cams = ", ".join(f"{v} {c['width']}x{c['height']}" for v, c in summary["cameras"].items())
    origins = ", ".join(f"{o}: {d['episodes']}" for o, d in summary["by_origin"].items()) or "none"
    print(
        f"{summary['path']}: {summary['episodes']} episodes, {summary['frames']} frames at {summary['fps']} fps; "
        f"cameras {cams}; action dim {summary['action_dim']}; by origin {origins}; "
        f"{len(summary['outcomes'])} judge(s)"
    )
    damage = summary["damage"]
    for line in damage["problems"]:
        print(f"  damaged: {line}")
    if damage["problems"]:
        n = len(damage["problems"])
        print(f"{summary['path']}: DAMAGED, {n} file(s) missing or cut short; `pilworld data verify` checks every byte")
    if args.json:
        print(json.dumps(summary))
    return 1 if damage["problems"] else 0


def _dataset_parts(path: Path) -> bool:
    """Whether ``path`` holds parts of a dataset (its tables or data), so a missing file is damage."""
    return (path / "meta" / "episodes").is_dir() or (path / "data").is_dir()


def _verify(args: argparse.Namespace) -> int:
    from pilworld.data.reader import DamagedDatasetError
    from pilworld.data.verify import verify

    try:
        report = verify(
            args.path, hash_files=not args.sizes_only, progress=not args.no_progress and sys.stderr.isatty()
        )
    except DamagedDatasetError as err:  # damaged metadata: exit 1 (damaged), not 2 (not a dataset)
        print(f"pilworld: error: {' '.join(str(err).split())}", file=sys.stderr)
        return 1
    for problem in report.problems:
        print(f"DAMAGED {problem.describe()}")
    print(report.summary())
    if args.json:
        print(json.dumps(report.to_json()))
    return 0 if report.ok else 1
