"""``pilworld bench control-video``: Γ throughput in one process (geometry + drawing, no file I/O)."""

from __future__ import annotations

import argparse
import time
from pathlib import Path
from typing import Any

import cv2
import numpy as np
from tqdm import tqdm

from pilworld.bench.common import machine_info
from pilworld.bench.flags import add_json, add_rig
from pilworld.bench.output import emit
from pilworld.config.rig import RigConfig
from pilworld.control_video import ControlVideo
from pilworld.control_video.examples import random_chunks
from pilworld.control_video.robot_render import BACKENDS
from pilworld.control_video.styles import STYLES, Style
from pilworld.options.parse import parse_size
from pilworld.types import ChunkSpec


def run_control_video_bench(
    rig_path: Path,
    *,
    chunks: int = 4000,
    batch: int = 64,
    size: tuple[int, int] = (128, 128),
    spec: ChunkSpec | None = None,
    repeats: int = 3,
    seed: int = 0,
    progress: bool = True,
) -> dict[str, Any]:
    """Render ``chunks`` random chunks in batches; report the best of ``repeats`` timed passes.

    The best pass is reported because the machine is shared (2 cores): slower passes measure other
    load, not Γ. The single-chunk path (``ControlVideo.__call__``, what a rollout calls once per
    round) is timed separately as latency.
    """
    if chunks < 1 or batch < 1 or repeats < 1:
        raise ValueError(f"chunks, batch and repeats must be ≥ 1, got {chunks}, {batch}, {repeats}")
    cv2.setNumThreads(1)  # one process, one thread: the figure a rollout worker gets
    spec = spec or ChunkSpec()
    rig = RigConfig.load(rig_path)
    rig = RigConfig.model_validate({**rig.model_dump(), "image_size": {"width": size[0], "height": size[1]}})
    gamma = ControlVideo.from_rig(rig, spec)
    data = random_chunks(chunks, spec.horizon, seed=seed).astype(np.float64)
    starts = range(0, chunks, batch)

    gamma.render_batch(data[: min(batch, chunks)])  # warm-up (imports, caches)
    passes: list[float] = []
    geometry_s: list[float] = []
    checksum = 0
    for r in tqdm(range(repeats), desc="bench control-video", unit="pass", disable=not progress):
        t0 = time.perf_counter()
        for s in starts:
            frames = gamma.render_batch(data[s : s + batch])
            if r == 0:
                checksum = (checksum * 31 + int(frames.sum(dtype=np.uint64))) % (1 << 61)
        passes.append(time.perf_counter() - t0)
        t0 = time.perf_counter()
        for s in starts:
            gamma.geometry(gamma.stride_aligned(data[s : s + batch]))
        geometry_s.append(time.perf_counter() - t0)

    latency = []
    for i in range(min(200, chunks)):
        t0 = time.perf_counter()
        gamma(data[i])
        latency.append(time.perf_counter() - t0)

    geo = gamma.geometry(gamma.stride_aligned(data))
    best = min(passes)
    n_frames = chunks * spec.frames
    return {
        "benchmark": "control-video",
        "frames_per_s": n_frames / best,
        "chunks_per_s": chunks / best,
        "ms_per_chunk_batched": 1e3 * best / chunks,
        "ms_per_chunk_single_p50": 1e3 * float(np.median(latency)),
        "geometry_share": min(geometry_s) / best,
        "image_size": list(size),
        "K": spec.frames,
        "stride": spec.stride,
        "chunks": chunks,
        "batch": batch,
        "repeats": repeats,
        "pass_seconds": passes,
        "markers_drawn_fraction": float(geo.marker.mean()),
        "markers_visible_fraction": float(geo.visible.mean()),
        "frames_checksum": checksum,
        "rig": rig.name,
        "processes": 1,
        **machine_info(),
    }


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Γ's options, and a Γ⁺ style's (``--backend``, ``--starts``, ``--chunks-per-start``, ``--world-model``)."""
    parser.add_argument(
        "--style",
        default="markers",
        help=f"control-video style: {', '.join(STYLES)} (default markers, the paper's Γ: throughput bench)",
    )
    parser.add_argument("--backend", choices=BACKENDS, default="analytic", help="robot renderer (Γ⁺ styles)")
    parser.add_argument("--starts", type=int, default=4, help="Γ⁺: held-out simulated starts (default 4)")
    parser.add_argument("--chunks-per-start", type=int, default=10, help="Γ⁺: random chunks per start (default 10)")
    parser.add_argument(
        "--world-model",
        type=Path,
        default=None,
        help="Γ⁺: world-model folder timed in the same run (default: v1, sim_small); 'none' skips it",
    )
    add_rig(parser)
    parser.add_argument("--chunks", type=int, default=4000, help="random chunks per timed pass (default 4000)")
    parser.add_argument("--batch", type=int, default=64, help="chunks per render_batch call (default 64)")
    parser.add_argument("--size", default=None, help="WIDTHxHEIGHT (default: 128x128 for markers, the rig's for Γ⁺)")
    parser.add_argument("--frames", "-K", type=int, default=15, help="K (default 15)")
    parser.add_argument("--stride", type=int, default=3, help="Δ (default 3)")
    parser.add_argument("--repeats", type=int, default=3, help="timed passes; the best is reported (default 3)")
    parser.add_argument("--seed", type=int, default=0)
    add_json(parser)


def run(args: argparse.Namespace) -> int:
    """Γ's throughput (markers), or one Γ⁺ chunk's latency for any other ``--style``."""
    spec = ChunkSpec(horizon=max(50, args.frames * args.stride), frames=args.frames, stride=args.stride)
    style = Style.parse(args.style)
    if style.name != "markers":
        # Imported here: the Γ⁺ bench loads the robot renderer and a world model, which Γ's markers never need.
        from pilworld.bench.gamma_plus import run_style

        return run_style(args, style, spec)
    result = run_control_video_bench(
        args.rig,
        chunks=args.chunks,
        batch=args.batch,
        size=parse_size(args.size or "128x128"),
        spec=spec,
        repeats=args.repeats,
        seed=args.seed,
        progress=not args.json,
    )
    line = (
        f"control-video: {result['frames_per_s']:.0f} frames/s ({result['image_size'][0]}x{result['image_size'][1]}, "
        f"K={result['K']}), {result['ms_per_chunk_single_p50']:.3f} ms per single chunk"
    )
    return emit(args, result, [line])
