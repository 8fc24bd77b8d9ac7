"""``pilworld data info``: what a dataset holds, from its metadata alone (no video is decoded)."""

from __future__ import annotations

from collections import Counter
from pathlib import Path
from typing import Any

from pilworld.data.outcomes import read_outcomes, summarize
from pilworld.data.reader import EpisodeStore


def disk_bytes(root: Path) -> int:
    """Bytes of every file under ``root``."""
    return sum(p.stat().st_size for p in root.rglob("*") if p.is_file())


def dataset_info(root: str | Path) -> dict[str, Any]:
    store = EpisodeStore(root)
    rows = store.episodes
    origin_eps: Counter[str] = Counter()
    origin_frames: Counter[str] = Counter()
    checkpoints: Counter[str] = Counter()
    for row in rows:
        origin = str(row.get("origin") or "real")  # datasets from elsewhere are recordings: real
        origin_eps[origin] += 1
        origin_frames[origin] += int(row["length"])
        checkpoints[str(row.get("checkpoint") or "")] += 1
    lengths = [int(r["length"]) for r in rows]
    return {
        "path": str(store.root),
        "codebase_version": store.info.get("codebase_version"),
        "robot_type": store.info.get("robot_type"),
        "episodes": store.num_episodes,
        "frames": store.num_frames,
        "fps": store.fps,
        "duration_s": store.num_frames / store.fps,
        "episode_length": {"min": min(lengths), "max": max(lengths)} if lengths else None,
        "cameras": {v: {"height": h, "width": w} for v, (h, w) in store.spec.views.items()},
        "video_mode": store.spec.video_mode,
        "state_dim": store.spec.state_dim,
        "action_dim": store.spec.action_dim,
        "tasks": len(store.tasks),
        "by_origin": {o: {"episodes": origin_eps[o], "frames": origin_frames[o]} for o in sorted(origin_eps)},
        "checkpoints": dict(sorted(checkpoints.items())),
        "outcomes": summarize(read_outcomes(store.root)),
        "disk_mb": round(disk_bytes(store.root) / 2**20, 3),
        "damage": _cheap_check(store.root),
    }


def _cheap_check(root: Path) -> dict[str, Any]:
    """Files missing or of the wrong size (no hashing: ``pilworld data verify`` reads every byte)."""
    from pilworld.data.verify import check_dataset

    check = check_dataset(root, hash_files=False)
    return {
        "problems": [p.describe() for p in check.problems],
        "episodes_damaged": sorted(check.damaged_episodes()),
        "no_manifest": check.no_manifest,
    }
