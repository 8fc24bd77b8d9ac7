"""Importer for LeRobot v3.0 datasets (ours or packed ones LeRobot wrote), through :class:`EpisodeStore`.

The store locates every episode (its rows in a shared data parquet, its span of a shared mp4 from
``videos/<key>/from_timestamp``). Here the mapping is applied on top: cameras are selected and
renamed, other state/action columns may be chosen, and frames are resized while they are decoded,
so converting a 720p dataset never holds its full-size frames. PiL-World labels (origin, subtask,
round, checkpoint, seed, extra) are carried over when the source has them.
"""

from __future__ import annotations

import json
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import numpy as np
import pyarrow as pa
from numpy.typing import NDArray

from pilworld.data import layout
from pilworld.data.convert.base import EpisodeSource, camera_size, provenance_entry, vector_column, vector_feature
from pilworld.data.convert.mapping import ConvertMapping
from pilworld.data.episode import Episode
from pilworld.data.reader import EpisodeStore
from pilworld.data.spec import ACTION_KEY, STATE_KEY
from pilworld.data.video_codec import decode_video


class LeRobotV30Source(EpisodeSource):
    """A LeRobot v3.0 folder, read one episode at a time."""

    format_name = "lerobot-v30"

    def __init__(self, path: Path, mapping: ConvertMapping) -> None:
        super().__init__(path, mapping)
        self.store = EpisodeStore(self.path)  # raises naming meta/info.json unless v3.0
        info = self.store.info
        info_path = str(self.path / layout.INFO)
        feats: dict[str, Any] = info.get("features") or {}
        self.source_fps = self.store.fps
        self.fps = mapping.fps or self.source_fps
        self.robot_type = mapping.robot_type or self.store.spec.robot_type

        self.state_key = mapping.state_key or STATE_KEY
        self.action_key = mapping.action_key or ACTION_KEY
        self.state_width, self.state_names = vector_feature(feats, self.state_key, "state", where=info_path)
        self.action_width, self.action_names = vector_feature(feats, self.action_key, "action", where=info_path)

        self.cameras = mapping.select_cameras(list(self.store.video_keys), source=info_path)
        self.views = {view: self.output_size(camera_size(feats[key])) for key, view in self.cameras.items()}
        self.video_path = str(info.get("video_path") or layout.VIDEO_PATH)

    def lengths(self) -> list[int]:
        return [int(row["length"]) for row in self.store.episodes]

    def provenance(self, position: int) -> dict[str, Any]:
        return provenance_entry(self.format_name, position)

    def iter_episodes(self, start: int = 0) -> Iterator[Episode]:
        for index in range(start, self.store.num_episodes):
            yield self._load(index)

    def _video(self, row: dict[str, Any], key: str) -> tuple[Path, float]:
        """(mp4 path, from_timestamp) of camera ``key`` for the episode of ``row``."""
        try:
            chunk, file = int(row[f"videos/{key}/chunk_index"]), int(row[f"videos/{key}/file_index"])
        except (KeyError, TypeError):
            where = self.path / layout.EPISODES_DIR
            raise ValueError(f"{where}: episode {row['episode_index']} has no video location for {key!r}") from None
        path = self.path / self.video_path.format(video_key=key, chunk_index=chunk, file_index=file)
        return path, float(row.get(f"videos/{key}/from_timestamp") or 0.0)

    def _load(self, index: int) -> Episode:
        row = self.store.episodes[index]
        table = self.store.frame_table(index)  # this episode's rows, also from a shared file
        T = table.num_rows
        where = f"{self.path} episode {index}"
        state = vector_column(table, self.state_key, self.state_width, where=where)
        action = vector_column(table, self.action_key, self.action_width, where=where)
        t0 = float(table.column("timestamp")[0].as_py()) if "timestamp" in table.column_names and T else 0.0

        images: dict[str, NDArray[np.uint8]] = {}
        for key, view in self.cameras.items():
            path, from_ts = self._video(row, key)
            frames = decode_video(path, start=from_ts + t0, count=T, fps=self.source_fps, size=self.mapping.resize)
            if frames.shape[1:3] != self.views[view]:
                raise ValueError(f"{path}: frames are {frames.shape[1:3]}, {layout.INFO} says {self.views[view]}")
            images[view] = frames

        cols = set(table.column_names)

        def first(name: str, default: Any) -> Any:
            return table.column(name)[0].as_py() if name in cols and T else row.get(name, default)

        task_index = first("task_index", None)
        task = self.store.tasks.get(int(task_index), "") if task_index is not None else ""
        if not task.strip():
            task = next((str(t) for t in row.get("tasks") or [] if str(t).strip()), "")
        if not task.strip():
            task = self.fallback_task(where)
        extra: dict[str, Any] = json.loads(row["extra"]) if row.get("extra") else {}
        extra.update(self.provenance(index))
        return Episode(
            images=images,
            state=state,
            action=action,
            task=task,
            origin=self.mapping.origin or str(first("origin", None) or "real"),
            subtask_index=int(first("subtask_index", 0) or 0),
            checkpoint=str(first("checkpoint", "") or ""),
            seed=int(first("seed", 0) or 0),
            round_index=_int_column(table, "round_index"),
            extra=extra,
        )


def _int_column(table: pa.Table, name: str) -> NDArray[np.int64] | None:
    if name not in table.column_names:
        return None
    return np.asarray(table.column(name).to_numpy(), dtype=np.int64)
