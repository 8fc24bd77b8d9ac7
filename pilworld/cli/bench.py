"""``pilworld bench <name>``: performance figures as JSON (never timed assertions in tests).

Every benchmark prints a human summary and, with ``--json``, one JSON object as its last line.
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path
from typing import Any

from pilworld.cli.control_video import parse_size
from pilworld.types import ChunkSpec

DEFAULT_RIG = Path(__file__).resolve().parents[2] / "configs" / "rig" / "sim_dual_ur5e.yaml"


def register(sub: Any) -> None:
    p: argparse.ArgumentParser = sub.add_parser("bench", help="run a benchmark and print JSON")
    benches = p.add_subparsers(dest="bench", metavar="NAME")
    benches.required = True

    cv = benches.add_parser("control-video", help="Γ throughput: frames per second in one process")
    cv.add_argument("--rig", type=Path, default=DEFAULT_RIG, help="rig config (default: the simulated rig)")
    cv.add_argument("--chunks", type=int, default=4000, help="random chunks per timed pass (default 4000)")
    cv.add_argument("--batch", type=int, default=64, help="chunks per render_batch call (default 64)")
    cv.add_argument("--size", default="128x128", help="WIDTHxHEIGHT (default 128x128)")
    cv.add_argument("--frames", "-K", type=int, default=15, help="K (default 15)")
    cv.add_argument("--stride", type=int, default=3, help="Δ (default 3)")
    cv.add_argument("--repeats", type=int, default=3, help="timed passes; the best is reported (default 3)")
    cv.add_argument("--seed", type=int, default=0)
    cv.add_argument("--json", action="store_true", help="print the result as one JSON object on the last line")
    cv.set_defaults(handler=_control_video)

    dt = benches.add_parser("data", help="episode store write/read frames per second and clip loader rate")
    dt.add_argument("--episodes", type=int, default=6, help="synthetic episodes (default 6)")
    dt.add_argument("--length", type=int, default=300, help="frames per episode (default 300)")
    dt.add_argument("--size", type=int, default=128, help="image side in pixels, 3 views (default 128)")
    dt.add_argument("--video-mode", default="h264", choices=["h264", "lossless", "av1"])
    dt.add_argument("--json", action="store_true", help="print the result as one JSON object on the last line")
    dt.set_defaults(handler=_data)


def _control_video(args: argparse.Namespace) -> int:
    from pilworld.bench.control_video import run_control_video_bench

    spec = ChunkSpec(horizon=max(50, args.frames * args.stride), frames=args.frames, stride=args.stride)
    result = run_control_video_bench(
        args.rig,
        chunks=args.chunks,
        batch=args.batch,
        size=parse_size(args.size),
        spec=spec,
        repeats=args.repeats,
        seed=args.seed,
        progress=not args.json,
    )
    print(
        f"control-video: {result['frames_per_s']:.0f} frames/s ({result['image_size'][0]}x{result['image_size'][1]}, "
        f"K={result['K']}), {result['ms_per_chunk_single_p50']:.3f} ms per single chunk"
    )
    if args.json:
        print(json.dumps(result))
    return 0


def _data(args: argparse.Namespace) -> int:
    from pilworld.bench.data import run_data_bench

    result = run_data_bench(
        episodes=args.episodes, length=args.length, size=args.size, video_mode=args.video_mode, progress=not args.json
    )
    print(
        f"data ({result['video_mode']}, 3 views at {args.size}x{args.size}): write {result['write_frames_per_s']:.0f} "
        f"frames/s, read {result['read_frames_per_s']:.0f} frames/s, clips {result['clips_per_s']:.0f}/s "
        f"({result['clips_per_s_cold']:.0f}/s while decoding)"
    )
    if args.json:
        print(json.dumps(result))
    return 0
