"""Importer for LeRobot v3.0 datasets (ours or packed ones LeRobot wrote), through :class:`EpisodeStore`.

The store locates every episode (its rows in a shared data parquet, its span of a shared mp4 from
``videos/<key>/from_timestamp``). Here the mapping is applied on top: cameras are selected and
renamed, other state/action columns may be chosen, and frames are resized while they are decoded,
so converting a 720p dataset never holds its full-size frames. PiL-World labels (origin, subtask,
round, checkpoint, seed, extra) are carried over when the source has them.
"""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from pilworld.data import layout
from pilworld.data.convert.base import EpisodeSource, camera_size, provenance_entry, vector_column, vector_feature
from pilworld.data.convert.mapping import ConvertMapping
from pilworld.data.episode import Episode
from pilworld.data.reader import EpisodeStore
from pilworld.data.spec import ACTION_KEY, IMAGE_PREFIX, STATE_KEY
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

    def lengths(self) -> list[int]:
        return [int(row["length"]) for row in self.store.episodes]

    def provenance(self, position: int) -> dict[str, Any]:
        return provenance_entry(self.format_name, position)

    def iter_episodes(self, start: int = 0) -> Iterator[Episode]:
        for index in range(start, self.store.num_episodes):
            yield self._load(index)

    def _load(self, index: int) -> Episode:
        table = self.store.frame_table(index)  # this episode's rows, also from a shared file
        T = table.num_rows
        where = f"{self.path} episode {index}"
        state = vector_column(table, self.state_key, self.state_width, where=where)
        action = vector_column(table, self.action_key, self.action_width, where=where)
        t0 = float(table.column("timestamp")[0].as_py()) if "timestamp" in table.column_names and T else 0.0

        images: dict[str, NDArray[np.uint8]] = {}
        for key, view in self.cameras.items():
            path, from_ts = self.store.video_file(index, key[len(IMAGE_PREFIX) :])
            frames = decode_video(path, start=from_ts + t0, count=T, fps=self.source_fps, size=self.mapping.resize)
            if frames.shape[1:3] != self.views[view]:
                raise ValueError(f"{path}: frames are {frames.shape[1:3]}, {layout.INFO} says {self.views[view]}")
            images[view] = frames

        labels = self.store.labels(index, table)
        labels["task"] = labels["task"] or self.fallback_task(where)
        labels["origin"] = self.mapping.origin or labels["origin"] or "real"
        labels["extra"].update(self.provenance(index))
        return Episode(images=images, state=state, action=action, **labels)
