"""The flags most benches share, worded once: ``--rig`` (the simulated rig by default) and ``--json``; and
the run folder of a bench with a ``--quick`` mode.

``--json`` is the output contract of :func:`pilworld.bench.output.emit`: the whole result as one JSON
object on the last line of stdout.
"""

from __future__ import annotations

import argparse
from pathlib import Path

from simrig.files import SIM_RIG

RIG_HELP = "rig config (default: the simulated rig)"
JSON_HELP = "print the result as one JSON object on the last line"


def add_rig(parser: argparse.ArgumentParser, text: str = RIG_HELP) -> None:
    parser.add_argument("--rig", type=Path, default=SIM_RIG, help=text)


def add_json(parser: argparse.ArgumentParser, text: str = JSON_HELP) -> None:
    parser.add_argument("--json", action="store_true", help=text)


def run_folder(args: argparse.Namespace, bench: str) -> Path:
    """``--out``, else ``bench_runs/<bench>-quick`` or ``-full``: a quick run never resumes a full one's folder."""
    out: Path = args.out or Path("bench_runs") / f"{bench}-{'quick' if args.quick else 'full'}"
    return out
