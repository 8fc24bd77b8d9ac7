"""``pilworld report RUN_DIR``: a paired run as one self-contained ``report.html`` (see docs/report.md)."""

from __future__ import annotations

import argparse
import json
from pathlib import Path
from typing import Any


def register(sub: Any) -> None:
    p: argparse.ArgumentParser = sub.add_parser(
        "report",
        help="write a self-contained report.html of a paired run (videos, verdicts, metrics, charts)",
        description="Write RUN_DIR/report.html: per pair the real and imagined videos of every view and the "
        "control video side by side, verdicts per judge and the first hallucination frame; the metrics of "
        "metrics.json, the real-vs-imagined success scatter and per-frame error curves. One file that opens "
        "offline (media embedded as data: URIs).",
    )
    p.add_argument("run_dir", type=Path, metavar="RUN_DIR", help="paired run folder (pilworld paired run --out)")
    p.add_argument("--out", type=Path, default=None, help="report file (default RUN_DIR/report.html)")
    p.add_argument(
        "--max-pairs",
        type=int,
        default=None,
        metavar="N",
        help="embed videos of the first N pairs only (default all); the others are listed without video",
    )
    p.add_argument(
        "--imagined",
        type=Path,
        action="append",
        default=[],
        metavar="DIR",
        help="attach an imagined-only run (pilworld imagine --out DIR; repeatable): metrics.json and the report "
        "then give each checkpoint's real success rate by PPI++ beside the classical interval",
    )
    p.add_argument(
        "--proxy-judge",
        default=None,
        metavar="ID",
        help="with --imagined: the judge whose imagined verdicts PPI++ uses as predictions, remembered for the run "
        "(default: the run's selected judge, else 'learned' where it judged the run, else 'vision')",
    )
    p.add_argument("--json", action="store_true", help="print the summary as one JSON object on the last line")
    p.set_defaults(handler=_report)


def _report(args: argparse.Namespace) -> int:
    from pilworld.io.run_folder import check_out_file
    from pilworld.report import build_report, report_stats

    if args.max_pairs is not None and args.max_pairs < 0:
        raise ValueError(f"--max-pairs: expected an integer >= 0, got {args.max_pairs}")
    if not (args.run_dir / "meta" / "info.json").is_file():
        raise ValueError(f"RUN_DIR: {args.run_dir}: not a run folder (no meta/info.json)")
    check_out_file(args.out or args.run_dir / "report.html", "--out", suffixes=(".html",))  # before the work
    if args.proxy_judge is not None and not args.imagined:
        raise ValueError("--proxy-judge: only with --imagined (the PPI++ estimate it is for needs imagined-only runs)")
    if args.imagined:
        from pilworld.metrics import write_metrics
        from pilworld.ppi.outcomes import attach_runs, read_run_outcomes
        from pilworld.ppi.section import check_outcomes

        runs = [*[str(r) for r in args.imagined]]
        if args.proxy_judge is not None:
            from pilworld.data.outcomes import judges_with_verdicts

            have = judges_with_verdicts(args.run_dir)
            if args.proxy_judge not in have:
                raise ValueError(f"--proxy-judge: {args.proxy_judge!r} has no verdicts in {args.run_dir} "
                                 f"(it has: {', '.join(have) or 'none'})")  # fmt: skip
        # n = 0 for a checkpoint (or a proxy judge without verdicts): refused before anything
        check_outcomes(read_run_outcomes(args.run_dir, runs, proxy=args.proxy_judge))
        attach_runs(args.run_dir, runs, proxy=args.proxy_judge)
        write_metrics(args.run_dir)
    path = build_report(args.run_dir, args.out, max_pairs=args.max_pairs)
    stats = report_stats(path)
    print(f"report: {path} ({stats['bytes'] / 1e6:.2f} MB, {stats['videos']} videos)")
    if args.json:
        print(json.dumps(stats))
    return 0
