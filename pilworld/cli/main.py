"""``pilworld`` entry point: parses the command line and turns user errors into one clear line.

Each command lives in its own module exposing ``register(subparsers)``; the parser it adds carries a
``handler(args) -> int`` default. Errors are one line on stderr, ``pilworld: error: …``, never a
traceback (``--debug`` or ``PILWORLD_DEBUG=1`` shows it instead):

* exit 2 — the user's input is wrong (bad files, bad shapes, invalid configs, unknown names);
* exit 1 — a run failed on something outside it: a policy server (unreachable, handshake failed,
  timeout, server error, connection closed, invalid actions or reply — :class:`PolicyError`, the line
  names the checkpoint and the kind) or a hardware run with no operator at a terminal
  (:class:`OperatorUnavailableError`), or a calibration collection a device fault or Ctrl-C stopped
  (:class:`CollectionStoppedError`). What a run stored before the failure stays; rerunning resumes.
"""

from __future__ import annotations

import argparse
import os
import sys
import traceback
from collections.abc import Sequence
from pathlib import Path

from pilworld import __version__
from pilworld.cli import (
    annotate,
    bench,
    calibrate,
    control_video,
    data,
    demo,
    imagine,
    judge,
    paired,
    policy,
    report,
    robot,
    sim,
    task,
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
    judge.register(sub)
    bench.register(sub)
    policy.register(sub)
    report.register(sub)
    robot.register(sub)
    sim.register(sub)
    task.register(sub)
    train.register(sub)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    args.argv = list(argv) if argv is not None else sys.argv[1:]  # for commands that re-launch themselves
    from hw_drivers.errors import RobotError
    from pilworld.calibration.rig_devices import CollectionStoppedError
    from pilworld.paired.operator import OperatorUnavailableError
    from pilworld.policies.base import PolicyError

    debug = bool(args.debug) or os.environ.get("PILWORLD_DEBUG", "").strip() not in ("", "0")
    try:
        _check_path_arguments(args)
        return int(args.handler(args))
    # Run failures, exit 1 — a policy, a missing operator, or the rig (a stale observation, a protective stop:
    # the drivers have already stopped the arms). Caught before ValueError/OSError, which are bad input.
    except (PolicyError, OperatorUnavailableError, RobotError, CollectionStoppedError) as err:
        return _report(err, 1, debug)
    except (ValueError, FileNotFoundError, OSError) as err:
        return _report(err, 2, debug)
    except KeyboardInterrupt:
        print("pilworld: interrupted", file=sys.stderr)
        return 130


def _check_path_arguments(args: argparse.Namespace) -> None:
    """Every path argument must be text the libraries can take: OpenCV, for one, crashes (SIGSEGV) on a
    byte that is not UTF-8. Refused before any command runs, naming the flag."""
    from pilworld.io.run_folder import check_path_text

    for dest, value in vars(args).items():
        for item in value if isinstance(value, list | tuple) else [value]:
            if isinstance(item, Path | str):
                positional = dest in _POSITIONAL or (dest == "out" and getattr(args, "command", "") == "data")
                flag = dest.upper() if positional else f"--{dest.replace('_', '-')}"
                check_path_text(item, flag)


_POSITIONAL = {"run_dir", "path", "source", "dataset", "run", "files", "file"}


def _report(err: BaseException, status: int, debug: bool) -> int:
    """The error as one line on stderr (with ``--debug``, its traceback first); the exit status stays the
    documented one either way."""
    if debug:
        traceback.print_exception(err)
    print(f"pilworld: error: {_one_line(err)}", file=sys.stderr)
    return status


def _one_line(err: BaseException) -> str:
    filename, strerror = getattr(err, "filename", None), getattr(err, "strerror", None)
    if not isinstance(err, OSError) and filename is not None and strerror:  # PyAV's FFmpegError (a ValueError)
        return f"{os.fsdecode(filename)}: {' '.join(str(strerror).split())} (damaged or not a media file)"
    if isinstance(err, OSError) and err.filename is not None and err.strerror:
        # "[Errno 17] File exists: 'x'" reads as "x: File exists" (PyAV's errors too: the file first)
        names = [os.fsdecode(err.filename)] + ([os.fsdecode(err.filename2)] if err.filename2 is not None else [])
        return f"{' -> '.join(names)}: {' '.join(err.strerror.split())}"
    if isinstance(err, OSError) and err.errno is not None and err.strerror:
        return " ".join(err.strerror.split())
    return " ".join(str(err).split()) or type(err).__name__


if __name__ == "__main__":  # pragma: no cover - python -m pilworld.cli.main
    sys.exit(main())
