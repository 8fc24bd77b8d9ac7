"""``pilworld data info|convert``: inspect and import episode datasets (LeRobot v3.0 layout)."""

from __future__ import annotations

import argparse
import json
from pathlib import Path
from typing import Any


def register(sub: Any) -> None:
    p: argparse.ArgumentParser = sub.add_parser("data", help="inspect and convert episode datasets")
    data = p.add_subparsers(dest="data_command", metavar="SUBCOMMAND")
    data.required = True

    info = data.add_parser("info", help="episodes, frames, cameras, origins and outcomes of a dataset")
    info.add_argument("path", type=Path, help="dataset folder (LeRobot v3.0 layout)")
    info.add_argument("--json", action="store_true", help="print the summary as one JSON object on the last line")
    info.set_defaults(handler=_info)

    from pilworld.cli.data_convert import add_convert_parser

    add_convert_parser(data)


def _info(args: argparse.Namespace) -> int:
    from pilworld.data.info import dataset_info

    summary = dataset_info(args.path)
    cams = ", ".join(f"{v} {c['width']}x{c['height']}" for v, c in summary["cameras"].items())
    origins = ", ".join(f"{o}: {d['episodes']}" for o, d in summary["by_origin"].items()) or "none"
    print(
        f"{summary['path']}: {summary['episodes']} episodes, {summary['frames']} frames at {summary['fps']} fps; "
        f"cameras {cams}; action dim {summary['action_dim']}; by origin {origins}; "
        f"{len(summary['outcomes'])} judge(s)"
    )
    if args.json:
        print(json.dumps(summary))
    return 0
