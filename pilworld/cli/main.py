"""``pilworld`` entry point: parses the command line and turns user errors into one clear line.

Each command lives in its own module exposing ``register(subparsers)``; the parser it adds carries a
``handler(args) -> int`` default. User errors (bad files, bad shapes, invalid configs) print
``pilworld: error: …`` and exit 2; ``--debug`` shows the traceback instead.
"""

from __future__ import annotations

import argparse
import sys
from collections.abc import Sequence

from pilworld import __version__
from pilworld.cli import (
    annotate,
    bench,
    calibrate,
    control_video,
    data,
    demo,
    imagine,
    paired,
    policy,
    report,
    robot,
    sim,
    train,
)


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="pilworld",
        description="Paired real/imagined closed-loop evaluation of VLA policies (PiL-World).",
    )
    parser.add_argument("--version", action="version", version=f"pilworld {__version__}")
    parser.add_argument("--debug", action="store_true", help="show full tracebacks on errors")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    sub.required = True
    annotate.register(sub)
    calibrate.register(sub)
    control_video.register(sub)
    demo.register(sub)
    data.register(sub)
    paired.register(sub)
    imagine.register(sub)
    bench.register(sub)
    policy.register(sub)
    report.register(sub)
    robot.register(sub)
    sim.register(sub)
    train.register(sub)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    args.argv = list(argv) if argv is not None else sys.argv[1:]  # for commands that re-launch themselves
    try:
        return int(args.handler(args))
    except (ValueError, FileNotFoundError, OSError) as err:
        if args.debug:
            raise
        print(f"pilworld: error: {err}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print("pilworld: interrupted", file=sys.stderr)
        return 130


if __name__ == "__main__":  # pragma: no cover - python -m pilworld.cli.main
    sys.exit(main())
