"""Importer for LeRobot v2.0 / v2.1 datasets: one parquet and one mp4 per camera per episode.

Layout (LeRobot ``src/lerobot/datasets/utils.py`` before v3.0, and RealSource World)::

    meta/info.json        codebase_version "v2.1" (or "v2.0"), fps, features, chunks_size,
                          data_path   "data/chunk-{episode_chunk:03d}/episode_{episode_index:06d}.parquet"
                          video_path  "videos/chunk-{episode_chunk:03d}/{video_key}/episode_{episode_index:06d}.mp4"
    meta/episodes.jsonl   {"episode_index": 0, "tasks": ["..."], "length": 266} per line
    meta/tasks.jsonl      {"task_index": 0, "task": "..."} per line
    data/…/episode_XXXXXX.parquet   per-frame rows: observation.state, action, timestamp, task_index, …
    videos/…/episode_XXXXXX.mp4     frame i at timestamp i / fps

``episode_chunk`` is ``episode_index // chunks_size``. Cameras stored as ``image`` features (PNG bytes
inside the parquet, older datasets) are read too.
"""

from __future__ import annotations

import json
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq
from numpy.typing import NDArray

from pilworld.data import layout
from pilworld.data.convert.base import (
    CAMERA_DTYPES,
    EpisodeSource,
    camera_size,
    provenance_entry,
    vector_column,
    vector_feature,
)
from pilworld.data.convert.frames import read_image_column
from pilworld.data.convert.mapping import ConvertMapping
from pilworld.data.episode import Episode
from pilworld.data.reader import read_info
from pilworld.data.spec import ACTION_KEY, STATE_KEY
from pilworld.data.video_codec import decode_video

VERSIONS = ("v2.0", "v2.1")
EPISODES_JSONL = "meta/episodes.jsonl"
TASKS_JSONL = "meta/tasks.jsonl"
DATA_PATH = "data/chunk-{episode_chunk:03d}/episode_{episode_index:06d}.parquet"
VIDEO_PATH = "videos/chunk-{episode_chunk:03d}/{video_key}/episode_{episode_index:06d}.mp4"


def read_jsonl(path: Path) -> list[dict[str, Any]]:
    """One JSON object per non-empty line; ``ValueError`` naming the file and line otherwise."""
    if not path.is_file():
        raise ValueError(f"{path}: missing (every LeRobot v2.x dataset has it)")
    rows: list[dict[str, Any]] = []
    for number, line in enumerate(path.read_text(encoding="utf-8").splitlines(), start=1):
        if not line.strip():
            continue
        try:
            row = json.loads(line)
        except json.JSONDecodeError as err:
            raise ValueError(f"{path}:{number}: not valid JSON: {err}") from None
        if not isinstance(row, dict):
            raise ValueError(f"{path}:{number}: expected a JSON object, got {type(row).__name__}")
        rows.append(row)
    return rows


class LeRobotV21Source(EpisodeSource):
    """A LeRobot v2.0/v2.1 folder, read one episode at a time."""

    format_name = "lerobot-v21"

    def __init__(self, path: Path, mapping: ConvertMapping) -> None:
        super().__init__(path, mapping)
        self.info = read_info(self.path)
        info_path = str(self.path / layout.INFO)
        version = self.info.get("codebase_version")
        if version not in VERSIONS:
            raise ValueError(f"{info_path}: codebase_version {version!r}; this importer reads {list(VERSIONS)}")
        feats: dict[str, Any] = self.info.get("features") or {}
        self.source_fps = int(self.info.get("fps") or 0)
        if self.source_fps <= 0:
            raise ValueError(f"{info_path}: field 'fps' missing or not positive")
        self.fps = mapping.fps or self.source_fps
        self.robot_type = mapping.robot_type or str(self.info.get("robot_type") or "")

        self.state_key = mapping.state_key or STATE_KEY
        self.action_key = mapping.action_key or ACTION_KEY
        self.state_width, self.state_names = vector_feature(feats, self.state_key, "state", where=info_path)
        self.action_width, self.action_names = vector_feature(feats, self.action_key, "action", where=info_path)

        available = [k for k, ft in feats.items() if ft.get("dtype") in CAMERA_DTYPES]
        self.cameras = mapping.select_cameras(available, source=info_path)  # source key → view
        self.camera_dtype = {key: str(feats[key]["dtype"]) for key in self.cameras}
        self.source_sizes: dict[str, tuple[int, int]] = {}
        for key in self.cameras:
            try:
                self.source_sizes[key] = camera_size(feats[key])
            except ValueError as err:
                raise ValueError(f"{info_path}: feature {key!r}: {err}") from None
        self.views = {view: self.output_size(self.source_sizes[key]) for key, view in self.cameras.items()}

        episodes = read_jsonl(self.path / EPISODES_JSONL)
        for number, row in enumerate(episodes, start=1):
            if not isinstance(row.get("episode_index"), int) or not isinstance(row.get("length"), int):
                raise ValueError(f"{self.path / EPISODES_JSONL}:{number}: needs integer 'episode_index' and 'length'")
        self.episodes = sorted(episodes, key=lambda r: int(r["episode_index"]))
        self.tasks: dict[int, str] = {}
        for number, row in enumerate(read_jsonl(self.path / TASKS_JSONL), start=1):
            if not isinstance(row.get("task_index"), int) or not isinstance(row.get("task"), str):
                raise ValueError(f"{self.path / TASKS_JSONL}:{number}: needs integer 'task_index' and string 'task'")
            self.tasks[int(row["task_index"])] = row["task"]
        self.chunks_size = int(self.info.get("chunks_size") or layout.CHUNKS_SIZE)
        self.data_path = str(self.info.get("data_path") or DATA_PATH)
        self.video_path = str(self.info.get("video_path") or VIDEO_PATH)

    def lengths(self) -> list[int]:
        return [int(r["length"]) for r in self.episodes]

    def provenance(self, position: int) -> dict[str, Any]:
        return provenance_entry(self.format_name, int(self.episodes[position]["episode_index"]))

    def iter_episodes(self, start: int = 0) -> Iterator[Episode]:
        for position in range(start, len(self.episodes)):
            yield self._load(position)

    def _load(self, position: int) -> Episode:
        meta = self.episodes[position]
        index = int(meta["episode_index"])
        chunk = index // self.chunks_size
        data = self.path / self.data_path.format(episode_chunk=chunk, episode_index=index)
        if not data.is_file():
            raise ValueError(f"{data}: data file of episode {index} is missing")
        table = pq.read_table(data)
        T = table.num_rows
        if int(meta["length"]) != T:
            raise ValueError(f"{data}: {T} rows, but {EPISODES_JSONL} gives episode {index} length {meta['length']}")
        if T == 0:
            raise ValueError(f"{data}: episode {index} has no frames")
        state = vector_column(table, self.state_key, self.state_width, where=str(data))
        action = vector_column(table, self.action_key, self.action_width, where=str(data))
        # Frame 0 of a v2.x episode file is at `timestamp[0]` (0 in practice).
        t0 = float(table.column("timestamp")[0].as_py()) if "timestamp" in table.column_names else 0.0

        images: dict[str, NDArray[np.uint8]] = {}
        for key, view in self.cameras.items():
            size = self.views[view]
            if self.camera_dtype[key] == "image":
                cells = table.column(key).to_pylist() if key in table.column_names else []
                if len(cells) != T:
                    raise ValueError(f"{data}: no column {key!r} for image feature of the same name")
                images[view] = read_image_column(
                    cells, size=size, resize=self.mapping.resize is not None, where=f"{data}: column {key!r}"
                )
                continue
            video = self.path / self.video_path.format(episode_chunk=chunk, video_key=key, episode_index=index)
            frames = decode_video(video, start=t0, count=T, fps=self.source_fps, size=self.mapping.resize)
            if frames.shape[1:3] != size:
                raise ValueError(f"{video}: frames are {frames.shape[1:3]}, {layout.INFO} says {size}")
            images[view] = frames

        task, extra = self._task(table, meta, where=f"{data}")
        extra.update(self.provenance(position))
        return Episode(
            images=images,
            state=state,
            action=action,
            task=task,
            origin=self.mapping.origin or "real",
            extra=extra,
        )

    def _task(self, table: pa.Table, meta: dict[str, Any], *, where: str) -> tuple[str, dict[str, Any]]:
        """The episode's instruction (its first frame's task) and, if it has several, all of them."""
        names: list[str] = []
        if "task_index" in table.column_names:
            for idx in dict.fromkeys(table.column("task_index").to_pylist()):  # distinct, in order
                if idx is not None and self.tasks.get(int(idx), "").strip():
                    names.append(self.tasks[int(idx)])
        if not names:
            names = [str(t) for t in meta.get("tasks") or [] if str(t).strip()]
        if not names:
            return self.fallback_task(where), {}
        return names[0], ({"tasks": names} if len(names) > 1 else {})
