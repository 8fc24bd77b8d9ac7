"""Appending episodes to a LeRobot v3.0 dataset, one committed episode at a time.

Commit protocol for episode ``e`` (every step is a write-then-rename, see :mod:`pilworld.io.atomic`):

1. its data parquet and one mp4 per view, under file number ``e`` — new files nobody references yet;
2. ``meta/tasks.parquet`` if the instruction is new (an unused task row is harmless);
3. the last ``meta/episodes`` file with the new row — **the commit point**: from here on the
   episode exists for every reader;
4. ``meta/info.json`` (totals) and ``meta/stats.json`` (aggregated statistics).

A writer killed anywhere leaves every committed episode readable. Opening a writer on an existing
dataset recovers: files of uncommitted episodes and temporary files are deleted, and info/stats are
recomputed from the episodes table, so a new writer appends with consistent indices. One writer at a
time: an exclusive lock on ``meta/.writer.lock`` (released by the kernel if the writer dies).
"""

from __future__ import annotations

import fcntl
import json
import shutil
from collections.abc import Callable, Mapping
from functools import partial
from pathlib import Path
from types import TracebackType
from typing import Any

import numpy as np
import pyarrow as pa
from numpy.typing import NDArray

from pilworld.data import layout
from pilworld.data.backup import back_up
from pilworld.data.episode import Episode
from pilworld.data.manifest import MANIFEST_COLUMN, META_MANIFEST, manifest_json, meta_manifest_text
from pilworld.data.reader import DatasetError, EpisodeStore
from pilworld.data.spec import ACTION_KEY, CODEBASE_VERSION, STATE_KEY, DatasetSpec, spec_difference
from pilworld.data.stats import aggregate, image_stats, to_jsonable, vector_stats
from pilworld.data.video_codec import encode_video
from pilworld.io.atomic import atomic_write, is_temporary, write_json, write_parquet


def _stat_columns(stats: dict[str, dict[str, NDArray[np.float64]]]) -> dict[str, Any]:
    """Per-episode stats as ``stats/<feature>/<stat>`` columns (nested lists), as LeRobot stores them."""
    return {f"stats/{feat}/{k}": v.tolist() for feat, s in stats.items() for k, v in s.items()}


def _stats_from_row(row: dict[str, Any]) -> dict[str, dict[str, NDArray[np.float64]]]:
    out: dict[str, dict[str, NDArray[np.float64]]] = {}
    for key, value in row.items():
        if key.startswith("stats/") and value is not None:
            feat, stat = key[len("stats/") :].rsplit("/", 1)
            out.setdefault(feat, {})[stat] = np.asarray(value, dtype=np.float64)
    return out


def tasks_table(names: list[str]) -> pa.Table:
    """``meta/tasks.parquet`` as LeRobot reads it: row i is task_index i, the task string is the *pandas
    index* (LeRobot looks a task up as ``tasks.iloc[task_index].name``), so the pandas metadata that
    ``DataFrame.to_parquet`` would write is added by hand (no pandas dependency)."""
    table = pa.table(
        {"task_index": pa.array(range(len(names)), pa.int64()), "__index_level_0__": pa.array(names, pa.string())}
    )
    pandas_md = {
        "index_columns": ["__index_level_0__"],
        "column_indexes": [],
        "columns": [
            {
                "name": "task_index",
                "field_name": "task_index",
                "pandas_type": "int64",
                "numpy_type": "int64",
                "metadata": None,
            },
            {
                "name": None,
                "field_name": "__index_level_0__",
                "pandas_type": "unicode",
                "numpy_type": "object",
                "metadata": None,
            },
        ],
        "creator": {"library": "pyarrow", "version": pa.__version__},
        "pandas_version": "2.2.0",
    }
    return table.replace_schema_metadata({b"pandas": json.dumps(pandas_md).encode()})


_META_FILES = (layout.TASKS, layout.INFO, layout.STATS, layout.PILWORLD)  # covered by meta/manifest.json


def check_store_spec(root: Path, spec: DatasetSpec | None) -> None:
    """Refuse a dataset at ``root`` whose spec is not ``spec``, naming what differs; reads only."""
    if spec is None or not (root / layout.INFO).is_file():
        return
    have = EpisodeStore(root).spec
    if have != spec:
        raise DatasetError(
            f"{root}: exists with a different spec ({spec_difference(have, spec)}); "
            "resume with the same settings, or choose a new folder"
        )


class EpisodeWriter:
    """Create or reopen a dataset and append :class:`Episode` objects to it."""

    def __init__(self, root: str | Path, spec: DatasetSpec | None = None, *, durable: bool = True) -> None:
        self.root = Path(root)
        self.durable = durable
        check_store_spec(self.root, spec)  # a dataset of another spec is refused before a byte is written
        (self.root / "meta").mkdir(parents=True, exist_ok=True)
        self._lock_fh = (self.root / layout.LOCK).open("a")
        try:
            fcntl.flock(self._lock_fh, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            self._lock_fh.close()
            raise DatasetError(f"{self.root}: another writer holds {layout.LOCK}") from None
        self.recovered_files = 0
        try:
            self._open(spec)
        except BaseException:
            self.close()  # never leave the lock held by a writer that failed to open
            raise

    def _open(self, spec: DatasetSpec | None) -> None:
        if (self.root / layout.INFO).is_file():
            store = EpisodeStore(self.root)
            if spec is not None and spec != store.spec:
                raise DatasetError(
                    f"{self.root}: exists with a different spec ({spec_difference(store.spec, spec)}); "
                    "resume with the same settings, or choose a new folder"
                )
            self.spec = store.spec
            self._rows = list(store.episodes)
            self._tasks = {name: idx for idx, name in store.tasks.items()}
            self._recover()
        else:
            if spec is None:
                raise DatasetError(f"{self.root}: no dataset here; pass a DatasetSpec to create one")
            self.spec = spec
            self._rows = []
            self._tasks = {}
            write_json(self.root / layout.PILWORLD, spec.to_json(), durable=self.durable)
            self._write_info()

    # ------------------------------------------------------------------ lifecycle

    def __enter__(self) -> EpisodeWriter:
        return self

    def __exit__(
        self, exc_type: type[BaseException] | None, exc: BaseException | None, tb: TracebackType | None
    ) -> None:
        self.close()

    def close(self) -> None:
        if not self._lock_fh.closed:
            fcntl.flock(self._lock_fh, fcntl.LOCK_UN)
            self._lock_fh.close()

    @property
    def num_episodes(self) -> int:
        return len(self._rows)

    @property
    def num_frames(self) -> int:
        return int(self._rows[-1]["dataset_to_index"]) if self._rows else 0

    # ------------------------------------------------------------------ recovery

    def _recover(self) -> None:
        """Delete what an interrupted writer left without committing, then rewrite info and stats."""
        n = len(self._rows)
        committed = {(int(r["data/chunk_index"]), int(r["data/file_index"])) for r in self._rows}
        removed = 0
        for path in list((self.root / "data").glob("chunk-*/file-*.parquet")) + list(
            (self.root / "videos").glob("*/chunk-*/file-*.mp4")
        ):
            c = int(path.parent.name.split("-")[1])
            f = int(path.stem.split("-")[1])
            if (c, f) not in committed and c * layout.CHUNKS_SIZE + f >= n:
                path.unlink()
                removed += 1
        for path in self.root.rglob("*"):
            if path.is_file() and is_temporary(path):
                path.unlink()
                removed += 1
        self.recovered_files = removed
        from pilworld.data.outcomes import drop_episode_outcomes, read_outcomes

        if (self.root / layout.OUTCOMES).is_file():  # verdicts on episodes the table no longer holds
            gone = {o.episode_index for o in read_outcomes(self.root) if o.episode_index >= n}
            if gone:
                drop_episode_outcomes(self.root, gone)
        self._write_info()

    # ------------------------------------------------------------------ writing

    def _task_index(self, task: str) -> int:
        if task not in self._tasks:
            self._tasks[task] = len(self._tasks)
            names = sorted(self._tasks, key=self._tasks.__getitem__)
            write_parquet(self.root / layout.TASKS, tasks_table(names), durable=self.durable)
        return self._tasks[task]

    def append(self, episode: Episode, *, video_files: Mapping[str, Path] | None = None) -> int:
        """Commit one episode; returns its episode index. Raises ``ValueError`` if it does not fit.

        ``video_files``: per view, an mp4 already holding exactly ``episode``'s frames in this dataset's
        video mode and fps (an episode copied from another dataset of the same spec); it is copied byte
        for byte instead of encoding the frames again, which is most of the cost of a copy.
        """
        return self._commit(len(self._rows), episode, video_files)

    def replace(self, index: int, episode: Episode, *, video_files: Mapping[str, Path] | None = None) -> int:
        """Rewrite committed episode ``index`` (one whose files were lost or damaged) with ``episode``.

        The new episode must have the stored length, since later episodes' frame indices follow from it.
        Its verdicts in the outcomes table are dropped first: they judged the old files. Each file is
        replaced by a rename and the row last, so a writer killed midway leaves an episode whose files
        disagree with its manifest — which is what a resumed run checks, and redoes.
        """
        if not 0 <= index < len(self._rows):
            raise IndexError(f"episode {index} out of range: {self.root} has {len(self._rows)} episodes")
        stored = int(self._rows[index]["length"])
        if episode.length != stored:
            raise DatasetError(
                f"{self.root}: episode {index} is {stored} frames long; its replacement has {episode.length}"
            )
        from pilworld.data.outcomes import drop_episode_outcomes

        drop_episode_outcomes(self.root, {index})
        return self._commit(index, episode, video_files)

    def _commit(self, e: int, episode: Episode, video_files: Mapping[str, Path] | None) -> int:
        episode.check(self.spec)
        for view, src in (video_files or {}).items():
            if view not in self.spec.views:
                raise ValueError(f"video_files: {view!r} is not a view of {self.root} ({sorted(self.spec.views)})")
            if not Path(src).is_file():
                raise FileNotFoundError(f"video_files: {view!r}: {src} does not exist")
        T = episode.length
        chunk, file = layout.chunk_file(e)
        first = int(self._rows[e]["dataset_from_index"]) if e < len(self._rows) else self.num_frames
        task_index = self._task_index(episode.task)
        fps = self.spec.fps

        # 1. files of the new episode
        table = pa.table(
            {
                STATE_KEY: pa.FixedSizeListArray.from_arrays(
                    pa.array(episode.state.reshape(-1), pa.float32()), self.spec.state_dim
                ),
                ACTION_KEY: pa.FixedSizeListArray.from_arrays(
                    pa.array(episode.action.reshape(-1), pa.float32()), self.spec.action_dim
                ),
                "timestamp": pa.array(np.arange(T, dtype=np.float32) / np.float32(fps), pa.float32()),
                "frame_index": pa.array(np.arange(T), pa.int64()),
                "episode_index": pa.array(np.full(T, e), pa.int64()),
                "index": pa.array(np.arange(first, first + T), pa.int64()),
                "task_index": pa.array(np.full(T, task_index), pa.int64()),
                "origin": pa.array([episode.origin] * T, pa.string()),
                "subtask_index": pa.array(np.full(T, int(episode.subtask_index)), pa.int64()),
                "round_index": pa.array(episode.rounds().astype(np.int64), pa.int64()),
                "checkpoint": pa.array([episode.checkpoint] * T, pa.string()),
                "seed": pa.array(np.full(T, int(episode.seed)), pa.int64()),
            }
        )
        files = [layout.data_path(self.root, chunk, file)]
        write_parquet(files[0], table, durable=self.durable)
        stats: dict[str, dict[str, NDArray[np.float64]]] = {
            STATE_KEY: vector_stats(episode.state),
            ACTION_KEY: vector_stats(episode.action),
        }
        row: dict[str, Any] = {
            "episode_index": e,
            "tasks": [episode.task],
            "length": T,
            "data/chunk_index": chunk,
            "data/file_index": file,
            "dataset_from_index": first,
            "dataset_to_index": first + T,
        }
        for view in self.spec.views:
            key = self.spec.video_key(view)
            path = layout.video_path(self.root, key, chunk, file)
            if video_files and view in video_files:
                write: Callable[[Path], object] = partial(shutil.copyfile, video_files[view])
            else:
                write = partial(encode_video, episode.images[view], fps=fps, mode=self.spec.video_mode)
            atomic_write(path, write, durable=self.durable)
            files.append(path)
            stats[key] = image_stats(episode.images[view])
            row.update(
                {
                    f"videos/{key}/chunk_index": chunk,
                    f"videos/{key}/file_index": file,
                    f"videos/{key}/from_timestamp": 0.0,
                    f"videos/{key}/to_timestamp": T / fps,
                }
            )
        for name, values in (
            ("timestamp", table.column("timestamp").to_numpy()),
            ("frame_index", table.column("frame_index").to_numpy()),
            ("episode_index", table.column("episode_index").to_numpy()),
            ("index", table.column("index").to_numpy()),
            ("task_index", table.column("task_index").to_numpy()),
        ):
            stats[name] = vector_stats(values)
        meta_number = e // layout.EPISODES_PER_META_FILE
        meta_chunk, meta_file = layout.chunk_file(meta_number)
        row["meta/episodes/chunk_index"] = meta_chunk
        row["meta/episodes/file_index"] = meta_file
        row.update(_stat_columns(stats))
        # Our per-episode labels, for `pilworld data info` without reading every data file.
        row.update(
            {
                "origin": episode.origin,
                "subtask_index": int(episode.subtask_index),
                "checkpoint": episode.checkpoint,
                "seed": int(episode.seed),
                "extra": json.dumps(episode.extra, sort_keys=True) if episode.extra else "",
                # sizes and sha256 of the files above, committed with the row (pilworld.data.manifest)
                MANIFEST_COLUMN: manifest_json(self.root, files),
            }
        )

        # 2–3. the commit point: rewrite the last episodes file with the new row
        rows = [*self._rows[:e], row, *self._rows[e + 1 :]]
        in_file = [r for r in rows if int(r["episode_index"]) // layout.EPISODES_PER_META_FILE == meta_number]
        # every row with every column: rows of an older dataset lack the newer ones (manifest), and
        # from_pylist would take the first row's keys as the schema
        keys = list(dict.fromkeys(k for r in in_file for k in r))
        table_rows = [{k: r.get(k) for k in keys} for r in in_file]
        write_parquet(
            layout.episodes_meta_path(self.root, meta_number), pa.Table.from_pylist(table_rows), durable=self.durable
        )
        self._rows = rows

        # 4. totals and statistics
        self._write_info()
        return e

    def _write_info(self) -> None:
        n = len(self._rows)
        info = {
            "codebase_version": CODEBASE_VERSION,
            "robot_type": self.spec.robot_type,
            "total_episodes": n,
            "total_frames": self.num_frames,
            "total_tasks": len(self._tasks),
            "chunks_size": layout.CHUNKS_SIZE,
            "data_files_size_in_mb": 100,
            "video_files_size_in_mb": 200,
            "fps": self.spec.fps,
            "splits": {"train": f"0:{n}"} if n else {},
            "data_path": layout.DATA_PATH,
            "video_path": layout.VIDEO_PATH,
            "features": self.spec.features(),
        }
        write_json(self.root / layout.INFO, info, durable=self.durable)
        if n:
            per_episode = [_stats_from_row(r) for r in self._rows]
            feats = sorted(set().union(*per_episode))
            agg = {f: aggregate([s[f] for s in per_episode if f in s]) for f in feats}
            write_json(self.root / layout.STATS, to_jsonable(agg), durable=self.durable)
        # after the commit: the metadata files that episodes' own manifests cannot cover
        meta_files = [*layout.episodes_meta_files(self.root), *(self.root / f for f in _META_FILES)]
        write_json(self.root / META_MANIFEST, meta_manifest_text(self.root, meta_files), durable=self.durable)
        # a second copy of every table, the manifest last (pilworld.data.backup): a resume restores from it
        rels = [p.relative_to(self.root).as_posix() for p in meta_files if p.is_file()]
        back_up(self.root, [*rels, META_MANIFEST], durable=self.durable)
