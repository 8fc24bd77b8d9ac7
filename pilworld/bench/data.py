"""``pilworld bench data``: episode store write/read throughput and the clip loader's rate.

Synthetic scene-like episodes (smooth background, moving coloured discs; 3 views at 128×128 by
default) are written to a temporary dataset, read back, and cut into training clips.
"""

from __future__ import annotations

import argparse
import tempfile
import time
from pathlib import Path
from typing import Any

import cv2
import numpy as np
from numpy.typing import NDArray
from tqdm import tqdm

from pilworld.bench.common import machine_info
from pilworld.bench.flags import add_json
from pilworld.bench.output import emit
from pilworld.data.clip_dataset import ClipDataset
from pilworld.data.episode import Episode
from pilworld.data.info import disk_bytes
from pilworld.data.reader import EpisodeStore
from pilworld.data.spec import DatasetSpec
from pilworld.data.writer import EpisodeWriter
from pilworld.types import DEFAULT_VIEWS


def synthetic_episode(length: int, seed: int, size: int) -> Episode:
    """Frames with a shaded table and three moving discs per view, like the simulated rig's."""
    rng = np.random.default_rng(seed)
    yy, xx = np.mgrid[0:size, 0:size].astype(np.float32) / size
    base = np.stack([90 + 60 * yy, 80 + 50 * yy, 70 + 40 * xx], axis=-1).astype(np.uint8)
    images: dict[str, NDArray[np.uint8]] = {}
    for v, view in enumerate(DEFAULT_VIEWS):
        start = rng.uniform(0.2, 0.8, size=(3, 2)) * size
        vel = rng.uniform(-0.6, 0.6, size=(3, 2))
        frames = np.empty((length, size, size, 3), dtype=np.uint8)
        for t in range(length):
            img = base.copy()
            for j, (p, dv) in enumerate(zip(start, vel, strict=True)):
                c = tuple(int(x) for x in np.clip(p + dv * t, 0, size - 1))
                color = ((200, 40, 40), (40, 180, 60), (50, 60, 200))[(j + v) % 3]
                cv2.circle(img, c, max(2, size // 16), color, -1, cv2.LINE_AA)
            frames[t] = img
        images[view] = frames
    joints = np.cumsum(rng.normal(0, 0.01, size=(length, 14)), axis=0).astype(np.float32)
    return Episode(images=images, state=joints, action=joints, task="sort the cubes by size.", seed=seed)


def run_data_bench(
    *, episodes: int = 6, length: int = 300, size: int = 128, video_mode: str = "h264", progress: bool = True
) -> dict[str, Any]:
    if episodes < 1 or length < 46:
        raise ValueError(f"need episodes ≥ 1 and length ≥ 46 (one clip), got {episodes}, {length}")
    eps = [synthetic_episode(length, s, size) for s in range(episodes)]
    n_frames = episodes * length
    with tempfile.TemporaryDirectory(prefix="pilworld-bench-data-") as tmp:
        root = Path(tmp) / "ds"
        spec = DatasetSpec(views={v: (size, size) for v in DEFAULT_VIEWS}, video_mode=video_mode)
        t0 = time.perf_counter()
        with EpisodeWriter(root, spec) as writer:
            for ep in tqdm(eps, desc="write", unit="episode", disable=not progress):
                writer.append(ep)
        write_s = time.perf_counter() - t0

        store = EpisodeStore(root)
        t0 = time.perf_counter()
        max_err = 0
        for i in tqdm(range(episodes), desc="read", unit="episode", disable=not progress):
            back = store.load(i)
            max_err = max(max_err, int(np.abs(back.images["cam_high"].astype(int) - eps[i].images["cam_high"]).max()))
        read_s = time.perf_counter() - t0

        clips = ClipDataset(root, cache_dir=Path(tmp) / "cache")
        t0 = time.perf_counter()
        for i in range(len(clips)):
            clips[i]
        cold_s = time.perf_counter() - t0
        order = np.random.default_rng(0).permutation(len(clips))
        warm_clips = ClipDataset(root, cache_dir=Path(tmp) / "cache")  # a fresh loader: on-disk cache only
        t0 = time.perf_counter()
        for i in order:
            warm_clips[int(i)]
        warm_s = time.perf_counter() - t0
        disk = disk_bytes(root)

    return {
        "benchmark": "data",
        "write_frames_per_s": n_frames / write_s,
        "read_frames_per_s": n_frames / read_s,
        "clips_per_s": len(clips) / warm_s,
        "clips_per_s_cold": len(clips) / cold_s,
        "views": len(DEFAULT_VIEWS),
        "image_size": [size, size],
        "video_mode": video_mode,
        "episodes": episodes,
        "frames": n_frames,
        "clips": len(clips),
        "dataset_mb": disk / 2**20,
        "bytes_per_frame": disk / n_frames,
        "max_abs_pixel_error": max_err,
        "processes": 1,
        **machine_info(),
    }


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--episodes", type=int, default=6, help="synthetic episodes (default 6)")
    parser.add_argument("--length", type=int, default=300, help="frames per episode (default 300)")
    parser.add_argument("--size", type=int, default=128, help="image side in pixels, 3 views (default 128)")
    parser.add_argument("--video-mode", default="h264", choices=["h264", "lossless", "av1"])
    add_json(parser)


def run(args: argparse.Namespace) -> int:
    """Write, read and clip rates in one line, then with ``--json`` the whole result."""
    result = run_data_bench(
        episodes=args.episodes, length=args.length, size=args.size, video_mode=args.video_mode, progress=not args.json
    )
    line = (
        f"data ({result['video_mode']}, 3 views at {args.size}x{args.size}): write {result['write_frames_per_s']:.0f} "
        f"frames/s, read {result['read_frames_per_s']:.0f} frames/s, clips {result['clips_per_s']:.0f}/s "
        f"({result['clips_per_s_cold']:.0f}/s while decoding)"
    )
    return emit(args, result, [line])
