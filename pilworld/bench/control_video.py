"""``pilworld bench control-video``: Γ throughput in one process (geometry + drawing, no file I/O)."""

from __future__ import annotations

import time
from pathlib import Path
from typing import Any

import cv2
import numpy as np
from tqdm import tqdm

from pilworld.bench.common import machine_info
from pilworld.config.rig import RigConfig
from pilworld.control_video import ControlVideo
from pilworld.control_video.examples import random_chunks
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
