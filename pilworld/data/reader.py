"""Reading a LeRobot v3.0 dataset: ours (one file per episode) or any packed one LeRobot wrote.

The episodes table (``meta/episodes/*.parquet``) is the authority: an episode exists when its row
does. Files a killed writer left behind without a row are invisible here (the next writer deletes
them).
"""

from __future__ import annotations

import json
from functools import cached_property
from pathlib import Path
from typing import Any

import numpy as np
import pyarrow as pa
import pyarrow.compute as pc
import pyarrow.parquet as pq
from numpy.typing import NDArray

from pilworld.data import layout
from pilworld.data.episode import Episode
from pilworld.data.spec import ACTION_KEY, CODEBASE_VERSION, IMAGE_PREFIX, STATE_KEY, DatasetSpec
from pilworld.data.video_codec import decode_video


class DatasetError(ValueError):
    """A dataset folder is missing, not v3.0, or inconsistent; the message names the file."""


class DamagedDatasetError(DatasetError):
    """A dataset file that is there but damaged (unparseable, of the wrong shape, cut short)."""


_INFO_NUMBERS = ("fps", "total_episodes", "total_frames", "total_tasks", "chunks_size")
_INFO_TEXTS = ("codebase_version", "data_path", "video_path", "robot_type")


def check_info_shape(info: object, path: Path) -> dict[str, Any]:
    """``info.json`` as a dict of the fields readers use, of the types they expect; one line otherwise."""
    if not isinstance(info, dict):
        raise DamagedDatasetError(f"{path}: damaged: expected a JSON object, found {type(info).__name__}")
    for key in ("fps", "features"):
        if key not in info:
            raise DamagedDatasetError(f"{path}: damaged: no {key!r}")
    for key in _INFO_NUMBERS:
        value = info.get(key)
        if value is not None and (isinstance(value, bool) or not isinstance(value, int | float)):
            raise DamagedDatasetError(f"{path}: damaged: {key!r} is {value!r}, expected a number")
    if "fps" in info and not info["fps"] > 0:
        raise DamagedDatasetError(f"{path}: damaged: 'fps' is {info['fps']!r}, expected a positive number")
    for key in _INFO_TEXTS:
        value = info.get(key)
        if value is not None and not isinstance(value, str):
            raise DamagedDatasetError(f"{path}: damaged: {key!r} is {value!r}, expected text")
    feats = info.get("features", {})
    if not isinstance(feats, dict):
        raise DamagedDatasetError(f"{path}: damaged: 'features' is {feats!r}, expected an object")
    for key, ft in feats.items():
        if not isinstance(ft, dict):
            raise DamagedDatasetError(f"{path}: damaged: feature {key!r} is {ft!r}, expected an object")
        shape = ft.get("shape")
        if shape is not None and (
            not isinstance(shape, list) or not all(isinstance(n, int) and not isinstance(n, bool) for n in shape)
        ):
            raise DamagedDatasetError(f"{path}: damaged: feature {key!r} has shape {shape!r}, expected integers")
        if "info" in ft and not isinstance(ft["info"], dict | None):
            raise DamagedDatasetError(f"{path}: damaged: feature {key!r} has info {ft['info']!r}")
    return info


def read_info(root: Path) -> dict[str, Any]:
    path = root / layout.INFO
    if not path.is_file():
        raise DatasetError(f"{root}: not a LeRobot dataset (no {layout.INFO})")
    try:
        info = json.loads(path.read_text(encoding="utf-8"))
    except (json.JSONDecodeError, UnicodeDecodeError) as err:
        raise DamagedDatasetError(f"{path}: not valid JSON: {err}") from None
    return check_info_shape(info, path)


def list_column(table: pa.Table, key: str, width: int) -> NDArray[np.float32]:
    """A list<float> column of ``table`` as float32 (rows, width)."""
    col = table.column(key).combine_chunks()
    values = np.asarray(col.flatten().to_numpy(zero_copy_only=False), dtype=np.float32)
    return values.reshape(len(col), width)


def _names(feature: dict[str, Any], prefix: str) -> tuple[str, ...]:
    """Feature names as a flat tuple (LeRobot allows a list, {"motors": [...]}, or None)."""
    n = int(feature["shape"][0])
    names = feature.get("names")
    if isinstance(names, dict):
        names = [x for group in names.values() for x in group]
    if not isinstance(names, list) or len(names) != n:
        names = [f"{prefix}_{i}" for i in range(n)]
    return tuple(str(x) for x in names)


def spec_from_info(info: dict[str, Any], pilworld_json: dict[str, Any] | None, *, source: str) -> DatasetSpec:
    """Our spec from ``meta/pilworld.json`` when present, else derived from LeRobot's features."""
    if pilworld_json is not None:
        return DatasetSpec.from_json(pilworld_json, source=source)
    feats: dict[str, Any] = info.get("features", {})
    views: dict[str, tuple[int, int]] = {}
    for key, ft in feats.items():
        if key.startswith(IMAGE_PREFIX):
            if ft.get("dtype") != "video":
                raise DatasetError(
                    f"{source}: feature {key!r} is stored as {ft.get('dtype')!r}; only video is supported"
                )
            h, w = int(ft["shape"][0]), int(ft["shape"][1])
            if ft.get("names") and list(ft["names"])[:1] == ["channels"]:  # some datasets store (C, H, W)
                h, w = int(ft["shape"][1]), int(ft["shape"][2])
            views[key[len(IMAGE_PREFIX) :]] = (h, w)
    for key in (STATE_KEY, ACTION_KEY):
        if key not in feats:
            raise DatasetError(f"{source}: feature {key!r} missing")
    codec = next((ft.get("info", {}).get("video.codec") for ft in feats.values() if ft.get("dtype") == "video"), None)
    mode = "av1" if codec == "av1" else "h264"
    return DatasetSpec(
        fps=int(info["fps"]),
        views=views,
        state_names=_names(feats[STATE_KEY], "state"),
        action_names=_names(feats[ACTION_KEY], "action"),
        video_mode=mode,
        robot_type=str(info.get("robot_type") or ""),
    )


class EpisodeStore:
    """Read-only view of a dataset folder."""

    def __init__(self, root: str | Path) -> None:
        self.root = Path(root)
        self.info = read_info(self.root)
        version = str(self.info.get("codebase_version", ""))
        if version != CODEBASE_VERSION:
            raise DatasetError(
                f"{self.root / layout.INFO}: codebase_version {version!r}; this reader needs {CODEBASE_VERSION!r} "
                "(convert older datasets with `pilworld data convert`)"
            )
        pj = self.root / layout.PILWORLD
        try:
            own = json.loads(pj.read_text(encoding="utf-8")) if pj.is_file() else None
        except (json.JSONDecodeError, UnicodeDecodeError) as err:
            raise DamagedDatasetError(f"{pj}: not valid JSON: {err}") from None
        try:
            self.spec = spec_from_info(
                self.info, own, source=str(pj) if own is not None else str(self.root / layout.INFO)
            )
        except DatasetError:
            raise
        except (KeyError, TypeError, ValueError, IndexError, AttributeError) as err:
            where = str(pj) if own is not None else str(self.root / layout.INFO)
            detail = " ".join(str(err).split())
            raise DamagedDatasetError(detail if detail.startswith(where) else f"{where}: damaged: {detail}") from None
        self.video_keys = [k for k, ft in self.info["features"].items() if ft.get("dtype") == "video"]
        # The dataset's own path templates (LeRobot's defaults match ours; other writers may differ).
        self.data_path = str(self.info.get("data_path") or layout.DATA_PATH)
        self.video_path = str(self.info.get("video_path") or layout.VIDEO_PATH)
        self._table_cache: tuple[Path, pa.Table] | None = None

    # ------------------------------------------------------------------ metadata

    @cached_property
    def episodes(self) -> list[dict[str, Any]]:
        """One dict per committed episode, ordered by episode_index."""
        files = layout.episodes_meta_files(self.root)
        if not files:
            return []
        tables = []
        for f in files:
            try:
                tables.append(pq.read_table(f))
            except (OSError, pa.ArrowException) as err:  # a truncated or overwritten file
                raise DamagedDatasetError(f"{f}: episodes table unreadable ({str(err).splitlines()[0]})") from None
        table = pa.concat_tables(tables, promote_options="permissive")
        rows = sorted(table.to_pylist(), key=lambda r: int(r["episode_index"]))
        for i, row in enumerate(rows):
            if int(row["episode_index"]) != i:
                raise DatasetError(f"{self.root / layout.EPISODES_DIR}: episode indices are not 0..N-1 (at {i})")
        return rows

    @cached_property
    def tasks(self) -> dict[int, str]:
        path = self.root / layout.TASKS
        if not path.is_file():
            return {}
        try:
            table = pq.read_table(path)
        except (OSError, pa.ArrowException) as err:  # a truncated or overwritten file
            raise DamagedDatasetError(f"{path}: tasks table unreadable ({str(err).splitlines()[0]})") from None
        if "task" in table.column_names:
            names = table.column("task").to_pylist()
        else:  # pandas index column, as LeRobot writes it
            index_col = next(c for c in table.column_names if c != "task_index")
            names = table.column(index_col).to_pylist()
        return {int(i): str(t) for i, t in zip(table.column("task_index").to_pylist(), names, strict=True)}

    @property
    def num_episodes(self) -> int:
        return len(self.episodes)

    @property
    def num_frames(self) -> int:
        return sum(int(r["length"]) for r in self.episodes)

    @property
    def fps(self) -> int:
        return int(self.info["fps"])

    def __len__(self) -> int:
        return self.num_episodes

    # ------------------------------------------------------------------ frames

    def _check_index(self, index: int) -> dict[str, Any]:
        if not 0 <= index < self.num_episodes:
            raise IndexError(f"episode {index} out of range: {self.root} has {self.num_episodes} episodes")
        return self.episodes[index]

    def frame_table(self, index: int) -> pa.Table:
        """The per-frame rows of one episode (all columns), in frame order."""
        row = self._check_index(index)
        path = self.root / self.data_path.format(
            chunk_index=int(row["data/chunk_index"]), file_index=int(row["data/file_index"])
        )
        if self._table_cache is not None and self._table_cache[0] == path:
            table = self._table_cache[1]
        else:
            if not path.is_file():
                raise DatasetError(f"{path}: data file of episode {index} is missing")
            table = pq.read_table(path)
            self._table_cache = (path, table)
        if "episode_index" in table.column_names:  # packed files hold several episodes
            table = table.filter(pc.equal(table.column("episode_index"), index))
        if table.num_rows != int(row["length"]):
            raise DatasetError(f"{path}: episode {index} has {table.num_rows} rows, expected {row['length']}")
        return table

    def video_file(self, index: int, view: str) -> tuple[Path, float]:
        """(mp4 path, from_timestamp) of one view (camera key without ``observation.images.``) of an episode."""
        row = self._check_index(index)
        key = IMAGE_PREFIX + view
        if key not in self.video_keys:
            raise KeyError(f"view {view!r} not in {self.root} (views: {sorted(self.spec.views)})")
        try:
            chunk, file = int(row[f"videos/{key}/chunk_index"]), int(row[f"videos/{key}/file_index"])
        except (KeyError, TypeError):
            where = self.root / layout.EPISODES_DIR
            raise DatasetError(f"{where}: episode {index} has no video location for {key!r}") from None
        path = self.root / self.video_path.format(video_key=key, chunk_index=chunk, file_index=file)
        return path, float(row.get(f"videos/{key}/from_timestamp") or 0.0)

    def own_video_file(self, index: int, view: str) -> Path | None:
        """The mp4 of ``view`` if it holds episode ``index`` and nothing else, else None.

        Such a file can be copied byte for byte into another dataset of the same spec instead of being
        decoded and encoded again (:meth:`EpisodeWriter.append`'s ``video_files``). Files packing several
        episodes (LeRobot conversions may) return None.
        """
        path, t0 = self.video_file(index, view)
        if t0 != 0.0:
            return None
        key = IMAGE_PREFIX + view
        where = (f"videos/{key}/chunk_index", f"videos/{key}/file_index")
        mine = tuple(self.episodes[index].get(k) for k in where)
        if sum(1 for row in self.episodes if tuple(row.get(k) for k in where) == mine) != 1:
            return None
        return path

    def labels(self, index: int, table: pa.Table) -> dict[str, Any]:
        """PiL-World labels of an episode from its frame rows (``table``) and episodes-table row.

        Returns ``task`` ("" when the dataset names none), ``origin`` (None when absent: a recording from
        elsewhere), ``subtask_index``, ``checkpoint``, ``seed``, ``round_index`` (None when absent), ``extra``.
        """
        row = self._check_index(index)
        cols = set(table.column_names)

        def first(name: str, default: Any) -> Any:
            return table.column(name)[0].as_py() if name in cols and table.num_rows else row.get(name, default)

        task_index = first("task_index", None)
        task = self.tasks.get(int(task_index), "") if task_index is not None else ""
        if not task.strip():
            task = next((str(t) for t in row.get("tasks") or [] if str(t).strip()), "")
        rounds = None
        if "round_index" in cols:
            rounds = np.asarray(table.column("round_index").to_numpy(zero_copy_only=False), dtype=np.int64)
        origin = first("origin", None)
        return {
            "task": task,
            "origin": str(origin) if origin else None,
            "subtask_index": int(first("subtask_index", 0) or 0),
            "checkpoint": str(first("checkpoint", "") or ""),
            "seed": int(first("seed", 0) or 0),
            "round_index": rounds,
            "extra": json.loads(row["extra"]) if row.get("extra") else {},
        }

    def frames(self, index: int, view: str, start: int = 0, count: int | None = None) -> NDArray[np.uint8]:
        """Decoded RGB frames ``start .. start+count`` of one view, uint8 (N, H, W, 3)."""
        length = int(self._check_index(index)["length"])
        if not 0 <= start < length:
            raise IndexError(f"frame {start} out of range for episode {index} of length {length}")
        count = length - start if count is None else min(count, length - start)
        path, t0 = self.video_file(index, view)
        out = decode_video(path, start=t0 + start / self.fps, count=count, fps=self.fps)
        if out.shape[0] != count:
            raise DatasetError(f"{path}: expected {count} frames from frame {start}, decoded {out.shape[0]}")
        return out

    def load(self, index: int, views: list[str] | None = None) -> Episode:
        """The whole episode: frames of the given views (default all), state, action and labels."""
        table = self.frame_table(index)
        labels = self.labels(index, table)
        return Episode(
            images={v: self.frames(index, v) for v in (views or list(self.spec.views))},
            state=list_column(table, STATE_KEY, self.spec.state_dim),
            action=list_column(table, ACTION_KEY, self.spec.action_dim),
            **{**labels, "origin": labels["origin"] or "real"},
        )
