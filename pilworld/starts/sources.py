"""Where ``pilworld imagine --starts SOURCE`` finds its starts.

``SOURCE`` may be

* a starts folder (``starts.json``: ``pilworld paired record-starts``),
* a paired run (its ``starts/`` folder: the very starts its branches ran from), or
* any episode store (a collected or converted dataset): each real episode gives the start at frame
  ``start_frame`` (default H_h) with the H_h frames before it as history.
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from pilworld.data.reader import EpisodeStore
from pilworld.starts.store import META_FILE, StartsError, StoredStart, read_meta, start_from_episode

PAIRED_STARTS = "starts"  # a paired run's own starts: RUN/starts/


@dataclass(frozen=True)
class StartsSource:
    """The starts of one source, in stored order, and what the folder says about the robot."""

    root: Path  # the folder the starts were read from
    kind: str  # "starts" | "paired" | "dataset"
    starts: tuple[StoredStart, ...]
    meta: dict[str, Any] | None  # starts.json (robot limits, chunk timing); None for a plain dataset

    def pick(self, start_id: str, checkpoint: str) -> StoredStart:
        """The start ``checkpoint`` runs from: the one recorded for it, else the scene's shared one."""
        same = [s for s in self.starts if s.start_id == start_id]
        if not same:
            raise StartsError(f"{self.root}: no start {start_id}")
        for wanted in (checkpoint, ""):
            for s in same:
                if s.checkpoint == wanted:
                    return s
        return same[0]  # another checkpoint's scene: the same layout, set up for that checkpoint's trial

    def scenes(self) -> list[str]:
        """Start ids in stored order, each once."""
        return list(dict.fromkeys(s.start_id for s in self.starts))


def _resolve(path: Path) -> tuple[Path, str]:
    if (path / META_FILE).is_file():
        return path, "starts"
    if (path / PAIRED_STARTS / META_FILE).is_file():
        return path / PAIRED_STARTS, "paired"
    if (path / "paired_config.json").is_file():
        raise StartsError(
            f"{path}: this paired run stored no starts (runs before starts were kept); rerun it with "
            "pilworld paired run, or record starts with pilworld paired record-starts"
        )
    if (path / "meta" / "info.json").is_file():
        return path, "dataset"
    if not path.exists():
        raise StartsError(f"--starts: {path} does not exist")
    raise StartsError(f"--starts: {path} holds no starts (no {META_FILE}, no paired run, no episode store)")


def load_starts(path: str | Path, *, history: int, start_frame: int | None = None) -> StartsSource:
    """Every start in ``path``; raises :class:`StartsError` naming what is missing."""
    root, kind = _resolve(Path(path))
    if start_frame is not None and kind != "dataset":
        raise StartsError(
            f"--start-frame: {path} holds recorded starts (a {'paired run' if kind == 'paired' else 'starts folder'}), "
            "each with its own start frame; --start-frame is for a plain episode store"
        )
    if start_frame is not None and start_frame < 0:
        raise StartsError(f"--start-frame: expected a frame index >= 0, got {start_frame}")
    store = EpisodeStore(root)
    fps = float(store.fps)
    starts: list[StoredStart] = []
    for i, row in enumerate(store.episodes):
        extra = json.loads(row.get("extra") or "{}")
        if kind == "dataset" and str(row.get("origin") or "real") != "real":
            continue  # an imagined episode's frames are no robot's start
        if kind != "dataset" and "start" not in extra:
            raise StartsError(f"{root}: episode {i} is not a stored start (no extra.start)")
        ep = store.load(i)
        starts.append(
            start_from_episode(
                ep, f"{root} episode {i}", start_frame=start_frame, history=history, fps=fps, episode_index=i
            )
        )
    if not starts:
        raise StartsError(f"--starts: {root} holds no starts")
    return StartsSource(root, kind, tuple(starts), read_meta(root))
