"""What a judge may see of a run: their own blinded queue of opaque item ids, and the validation of labels.

Every judge gets all episodes of the run (both branches), or the subset the app was started with (the
episodes a learned judge abstained on), in an order of their own, shuffled with a seed derived from the
run's secret and the judge number, so it survives restarts but tells nothing.
An item id is ``HMAC(secret, "judge:episode")[:16]`` in hex: different per judge, and neither the order
nor the episode index can be read from it. The judge-facing JSON carries only frames, fps, the
instruction (the same in both branches), view names and the judge's own label.
"""

from __future__ import annotations

import json
import random
import threading
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from pilworld.annotate.store import AnnotationStore, Label
from pilworld.data.reader import DatasetError, EpisodeStore
from pilworld.judges.hallucination_checks import CATEGORIES
from pilworld.report.media import ordered_views

LABEL_FIELDS = ("success", "first_hallucination_frame", "category")
MAX_BODY = 4096


class LabelError(ValueError):
    """A label body that does not validate; ``field`` names what is wrong."""

    def __init__(self, field: str, message: str) -> None:
        super().__init__(f"{field}: {message}")
        self.field = field


@dataclass(frozen=True)
class EpisodeInfo:
    index: int
    num_frames: int
    instruction: str


def open_dataset(run_dir: str | Path) -> EpisodeStore:
    """The run's episode store; ``DatasetError`` naming the folder when it is not one (or is empty)."""
    root = Path(run_dir)
    if not root.is_dir():
        raise DatasetError(f"RUN_DIR: {root} is not a folder")
    store = EpisodeStore(root)
    if store.num_episodes == 0:
        raise DatasetError(f"RUN_DIR: {root} holds no episodes to judge")
    return store


class Catalog:
    """The run's episodes and every judge's queue."""

    def __init__(self, dataset: EpisodeStore, store: AnnotationStore, episodes: Sequence[int] | None = None) -> None:
        self.dataset = dataset
        n = dataset.num_episodes
        self.episodes = list(range(n)) if episodes is None else sorted(set(episodes))
        bad = [e for e in self.episodes if not 0 <= e < n]
        if bad:
            raise ValueError(f"episodes {bad[:10]} are not in {dataset.root} (it has {n} episodes)")
        self.store = store
        self.views = ordered_views(list(dataset.spec.views))
        self.fps = dataset.fps
        self._instructions: dict[int, str] = {}
        self._lock = threading.Lock()
        self._queues: dict[int, list[int]] = {}
        self._ids: dict[int, dict[str, int]] = {}  # judge → item id → episode index

    @property
    def num_episodes(self) -> int:
        return self.dataset.num_episodes

    def num_frames(self, episode: int) -> int:
        return int(self.dataset.episodes[episode]["length"])

    def instruction(self, episode: int) -> str:
        with self._lock:
            if episode not in self._instructions:
                # reading the frame table is the reliable way (tasks.parquet or the episodes row's list)
                labels = self.dataset.labels(episode, self.dataset.frame_table(episode))
                self._instructions[episode] = str(labels["task"])
            return self._instructions[episode]

    def item_id(self, judge: int, episode: int) -> str:
        return self.store.derive(f"{judge}:{episode}")[:16]

    def queue(self, judge: int) -> list[int]:
        """Episode indices in this judge's order."""
        with self._lock:
            if judge not in self._queues:
                order = list(self.episodes)
                random.Random(self.store.derive(f"order:{judge}")).shuffle(order)
                self._queues[judge] = order
                self._ids[judge] = {self.item_id(judge, e): e for e in order}
            return self._queues[judge]

    def episode_of(self, judge: int, item: str) -> int | None:
        """The episode behind one of this judge's item ids; None for any other string."""
        self.queue(judge)
        return self._ids[judge].get(item)

    def item_json(self, judge: int, episode: int, label: Label | None) -> dict[str, Any]:
        item = self.item_id(judge, episode)
        return {
            "id": item,
            "num_frames": self.num_frames(episode),
            "fps": self.fps,
            "instruction": self.instruction(episode),
            "views": list(self.views),
            "media": {v: f"/media/{item}/{v}.mp4" for v in self.views},
            "categories": list(CATEGORIES),
            "label": None if label is None else label.to_json(),
        }


def parse_label(body: bytes, num_frames: int) -> Label:
    """A label from a PUT body; ``LabelError`` naming the field for anything but an exact, valid object."""
    if len(body) > MAX_BODY:
        raise LabelError("body", f"larger than {MAX_BODY} bytes")
    try:
        value = json.loads(body.decode("utf-8"))
    except (UnicodeDecodeError, json.JSONDecodeError):
        raise LabelError("body", "not valid JSON") from None
    if not isinstance(value, dict):
        raise LabelError("body", "expected a JSON object")
    unknown = sorted(set(value) - set(LABEL_FIELDS))
    if unknown:
        raise LabelError(unknown[0], f"unknown field (allowed: {', '.join(LABEL_FIELDS)})")
    if "success" not in value:
        raise LabelError("success", "required")
    # frame and category may be left out: absent means null (no hallucination seen)
    success, frame, category = value["success"], value.get("first_hallucination_frame"), value.get("category")
    if not isinstance(success, bool):
        raise LabelError("success", "expected true or false")
    if frame is not None and (isinstance(frame, bool) or not isinstance(frame, int) or not 0 <= frame < num_frames):
        raise LabelError("first_hallucination_frame", f"expected null or an integer in [0, {num_frames - 1}]")
    if frame is None and category is not None:
        raise LabelError("category", "must be null when first_hallucination_frame is null")
    if frame is not None and category not in CATEGORIES:
        raise LabelError("category", f"expected one of {list(CATEGORIES)} with a hallucination frame")
    return Label(success, frame, category)
