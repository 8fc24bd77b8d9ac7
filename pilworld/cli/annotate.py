"""``pilworld annotate serve|export|status RUN_DIR``: blinded judging by people (see docs/annotate.md)."""

from __future__ import annotations

import argparse
import signal
import threading
from pathlib import Path
from types import FrameType
from typing import Any


def register(sub: Any) -> None:
    p: argparse.ArgumentParser = sub.add_parser(
        "annotate",
        help="blinded web app for human judges: success and first hallucination frame per episode",
        description="Human judges label every episode of a run (success; first hallucination frame and its "
        "category), blinded to origin, checkpoint and each other. Labels live in RUN_DIR/annotations.sqlite and "
        "are exported into the run's outcomes as judges human_1 … human_N.",
    )
    verbs = p.add_subparsers(dest="verb", metavar="VERB")
    verbs.required = True

    s = verbs.add_parser("serve", help="start the judging web app (Ctrl-C stops it and exports)")
    s.add_argument("run_dir", type=Path, metavar="RUN_DIR", help="a run folder (episode store)")
    s.add_argument(
        "--judges",
        type=int,
        default=None,
        metavar="N",
        help="number of judges (needed the first time) [1..100: each judge is a person with their own token]",
    )
    s.add_argument("--host", default="127.0.0.1", help="address to listen on (default 127.0.0.1)")
    s.add_argument("--port", type=int, default=8765, help="port (default 8765; 0 = any free port)")
    s.add_argument("--allow-remote", action="store_true", help="allow a non-loopback --host (plain HTTP!)")
    s.add_argument("--new-tokens", action="store_true", help="issue every judge a new token (old ones stop working)")
    s.add_argument("--no-export", action="store_true", help="do not export when stopped")
    s.add_argument(
        "--abstained",
        action="store_true",
        help="queue only the episodes the learned judge abstained on (pilworld judge apply JUDGE RUN_DIR)",
    )
    s.set_defaults(handler=_serve)

    e = verbs.add_parser("export", help="labels -> outcomes (human_1 … human_N), then metrics.json and report.html")
    e.add_argument("run_dir", type=Path, metavar="RUN_DIR")
    e.add_argument("--no-report", action="store_true", help="recompute metrics.json only")
    e.set_defaults(handler=_export)

    t = verbs.add_parser("status", help="per judge: labelled k of n")
    t.add_argument("run_dir", type=Path, metavar="RUN_DIR")
    t.set_defaults(handler=_status)


def _print_export(run_dir: Path, report: bool = True) -> None:
    from pilworld.annotate.export import export_labels

    result = export_labels(run_dir, report=report)
    counts = ", ".join(f"{j} {n}" for j, n in result.labels.items()) or "no judges"
    print(f"exported labels to {result.outcomes_file}: {counts}" + (f"; {result.removed} stale rows removed"
                                                                    if result.removed else ""), flush=True)  # fmt: skip
    if result.skipped:
        print(f"not recomputed: {result.skipped}", flush=True)
    if result.metrics:
        print(f"metrics: {result.metrics}", flush=True)
    if result.report:
        print(f"report: {result.report}", flush=True)


def abstained_episodes(run_dir: Path) -> list[int]:
    """The episodes the learned judge applied to ``run_dir`` left to people; one line naming what is missing."""
    from pilworld.judges.learned.apply import RECORD, read_record

    record = read_record(run_dir)
    if record is None:
        raise ValueError(
            f"--abstained: no learned judge was applied to {run_dir} ({run_dir / RECORD} is missing); "
            f"run `pilworld judge apply JUDGE {run_dir}` first"
        )
    if not record.get("complete"):
        raise ValueError(
            f"--abstained: the learned judge's pass over {run_dir} did not finish; "
            f"run `pilworld judge apply JUDGE {run_dir}` again to complete it"
        )
    return [int(e) for e in record["abstained"]]


def _serve(args: argparse.Namespace) -> int:
    from pilworld.annotate.server import AnnotationServer
    from pilworld.options.bounds import JUDGES, check_count

    check_count(args.judges, "--judges", JUDGES)
    episodes = abstained_episodes(args.run_dir) if args.abstained else None
    if episodes == []:
        print(f"the learned judge answered every episode of {args.run_dir}: nothing is left to people", flush=True)
        return 0
    server = AnnotationServer(
        args.run_dir,
        judges=args.judges,
        host=args.host,
        port=args.port,
        allow_remote=args.allow_remote,
        new_tokens=args.new_tokens,
        episodes=episodes,
    )
    judges = server.store.judges()
    total = len(server.app.catalog.episodes)
    print(f"judging {total} episodes of {args.run_dir} at {server.url} ({len(judges)} judges)", flush=True)
    for j in judges:
        if j in server.tokens:
            print(f"  Judge {j}: {server.login_url(server.tokens[j])}", flush=True)
        else:
            print(
                f"  Judge {j}: token from an earlier start (still valid; only its hash is stored, so it cannot be "
                "shown again; --new-tokens issues new ones)",
                flush=True,
            )
    print("Give each judge only their own link. Ctrl-C stops the server and exports the labels.", flush=True)

    stop = threading.Event()
    catalog = server.app.catalog
    warm = threading.Thread(  # encode videos ahead of the judges, in judge 1's order
        target=server.app.media.warm, args=(catalog.queue(judges[0]), catalog.views, stop), daemon=True
    )
    warm.start()

    def _terminate(signum: int, frame: FrameType | None) -> None:
        raise KeyboardInterrupt  # SIGTERM stops as cleanly as Ctrl-C

    previous = signal.signal(signal.SIGTERM, _terminate)
    # Ctrl-C too, explicitly: a process started in the background by a non-interactive shell (a CI script,
    # `cmd &`) inherits SIGINT ignored, and Python then installs no KeyboardInterrupt handler of its own:
    # the server would go on serving after the Ctrl-C this prompt promises to honour.
    previous_int = signal.signal(signal.SIGINT, _terminate)
    try:
        server.serve_forever()
    except KeyboardInterrupt:
        print("stopping", flush=True)
    finally:
        signal.signal(signal.SIGTERM, previous)
        signal.signal(signal.SIGINT, previous_int)
        stop.set()
        server.httpd.server_close()
    if not args.no_export:
        if any(server.store.counts().values()):
            _print_export(args.run_dir)
        else:
            print("no labels yet: nothing to export", flush=True)
    return 0


def _export(args: argparse.Namespace) -> int:
    _print_export(args.run_dir, report=not args.no_report)
    return 0


def _status(args: argparse.Namespace) -> int:
    from pilworld.annotate.catalog import open_dataset
    from pilworld.annotate.export import open_existing

    total = open_dataset(args.run_dir).num_episodes
    store = open_existing(args.run_dir)
    counts = store.counts()
    if not counts:  # a first start stopped before its judges were made
        print(
            f"{args.run_dir}: no judges yet (a first `pilworld annotate serve` was stopped early); "
            "start one with `pilworld annotate serve RUN_DIR --judges N`"
        )
    for judge, done in counts.items():
        print(f"Judge {judge}: labelled {done} of {total}")
    return 0
