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

    sm = benches.add_parser(
        "sim", help="simulated rig: physics steps/s, render ms/view, realtime factor, success rates"
    )
    sm.add_argument("--rig", type=Path, default=DEFAULT_RIG, help="rig config (default: the simulated rig)")
    sm.add_argument("--task", default="sort_cubes", help="task for the speed figures (default sort_cubes)")
    sm.add_argument("--subtasks", type=int, default=0, help="also measure success rates over N subtask starts per task")
    sm.add_argument("--tasks", default="all", help="comma-separated tasks for the success rates (default all)")
    sm.add_argument("--checkpoints", default="all", help="comma-separated scripted checkpoints (default all)")
    sm.add_argument("--workers", type=int, default=None, help="processes for the success rates (default: CPUs)")
    sm.add_argument("--json", action="store_true", help="print the result as one JSON object on the last line")
    sm.set_defaults(handler=_sim)


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


def _names(value: str, all_names: list[str], what: str) -> list[str]:
    if value.strip() == "all":
        return all_names
    names = [v.strip() for v in value.split(",") if v.strip()]
    bad = [n for n in names if n not in all_names]
    if bad or not names:
        raise ValueError(f"{what}: unknown {bad or value!r}; choose from {', '.join(all_names)} or 'all'")
    return names


def _sim(args: argparse.Namespace) -> int:
    from hw_drivers.sim.tasks import TASK_NAMES
    from pilworld.bench.sim import run_sim_bench
    from pilworld.policies.scripted import CHECKPOINTS

    tasks = _names(args.tasks, list(TASK_NAMES), "--tasks")
    ckpts = _names(args.checkpoints, [c.name for c in CHECKPOINTS], "--checkpoints")
    result = run_sim_bench(
        str(args.rig),
        task=args.task,
        subtasks=args.subtasks,
        tasks=tasks,
        checkpoints=ckpts,
        workers=args.workers,
        progress=not args.json,
    )
    print(
        f"sim: {result['physics_steps_per_s']:.0f} physics steps/s, {result['render_ms_per_view']:.1f} ms per view, "
        f"realtime factor {result['realtime_factor']:.1f}"
    )
    for task, rates in result.get("success_rates", {}).items():
        print(f"  {task}: " + ", ".join(f"{c} {r:.2f}" for c, r in rates.items()))
    if args.json:
        print(json.dumps(result))
    return 0
