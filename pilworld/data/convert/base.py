"""What every importer provides: the output layout of a source and its episodes, one at a time."""

from __future__ import annotations

from abc import ABC, abstractmethod
from collections.abc import Iterator
from pathlib import Path
from typing import Any, ClassVar

import numpy as np
import pyarrow as pa
from numpy.typing import NDArray

from pilworld.data.convert.mapping import ConvertMapping
from pilworld.data.episode import Episode
from pilworld.data.spec import DatasetSpec

CAMERA_DTYPES = ("video", "image")  # LeRobot feature dtypes that hold camera frames


def feature_names(names: Any, width: int, prefix: str) -> tuple[str, ...]:
    """Per-dimension names of a vector feature: the source's when usable, else ``prefix_0..``.

    LeRobot stores names as a list, as ``{"motors": [...]}`` (v2.0), or not at all; names that do
    not give one unique string per dimension are replaced (a spec needs unique names).
    """
    if isinstance(names, dict):
        names = [x for group in names.values() if isinstance(group, list) for x in group]
    if isinstance(names, list | tuple) and len(names) == width:
        out = tuple(str(x) for x in names)
        if len(set(out)) == width and all(out):
            return out
    return tuple(f"{prefix}_{i}" for i in range(width))


def provenance_entry(fmt: str, episode: int, file: str | None = None) -> dict[str, Any]:
    """``Episode.extra`` entry naming where an episode came from (also used to check a resume)."""
    entry: dict[str, Any] = {"format": fmt, "episode": episode}
    if file is not None:
        entry["file"] = file
    return {"converted_from": entry}


class EpisodeSource(ABC):
    """A source dataset seen through a :class:`ConvertMapping`.

    Subclasses set the output layout in ``__init__`` (reading only metadata) and decode episodes
    lazily in :meth:`iter_episodes`, so a conversion holds one episode in memory at a time.
    """

    format_name: ClassVar[str]  # the --format value

    # Set by every subclass's __init__:
    fps: int  # output frame rate (the mapping's override, else the source's)
    views: dict[str, tuple[int, int]]  # our view name → output (height, width)
    state_names: tuple[str, ...]
    action_names: tuple[str, ...]
    robot_type: str

    def __init__(self, path: Path, mapping: ConvertMapping) -> None:
        self.path = Path(path)
        self.mapping = mapping

    @abstractmethod
    def lengths(self) -> list[int]:
        """Frames of every source episode, in conversion order."""

    @abstractmethod
    def iter_episodes(self, start: int = 0) -> Iterator[Episode]:
        """Episodes ``start``, ``start + 1``, … (earlier ones are skipped without decoding them)."""

    @abstractmethod
    def provenance(self, position: int) -> dict[str, Any]:
        """``Episode.extra`` entry naming source episode ``position`` (see :func:`provenance_entry`)."""

    def __len__(self) -> int:
        return len(self.lengths())

    def spec(self, video_mode: str) -> DatasetSpec:
        """The spec of the converted dataset."""
        return DatasetSpec(
            fps=self.fps,
            views=dict(self.views),
            state_names=self.state_names,
            action_names=self.action_names,
            video_mode=video_mode,
            robot_type=self.robot_type,
        )

    def output_size(self, size: tuple[int, int]) -> tuple[int, int]:
        """Output (height, width) of a camera whose frames are ``size``."""
        return self.mapping.resize if self.mapping.resize is not None else size

    def fallback_task(self, where: str) -> str:
        """The mapping's instruction for an episode without one; ``ValueError`` naming ``where`` if unset."""
        if self.mapping.task is None:
            raise ValueError(f"{where}: no instruction in the source; pass --task TEXT or set 'task' in the mapping")
        return self.mapping.task


def vector_column(table: pa.Table, key: str, width: int, *, where: str) -> NDArray[np.float32]:
    """Column ``key`` of ``table`` as float32 (rows, width): a list column, or a scalar one when width is 1."""
    if key not in table.column_names:
        raise ValueError(f"{where}: no column {key!r} (columns: {table.column_names})")
    col = table.column(key).combine_chunks()
    rows = len(col)
    if pa.types.is_list(col.type) or pa.types.is_large_list(col.type) or pa.types.is_fixed_size_list(col.type):
        if col.null_count:
            raise ValueError(f"{where}: column {key!r} has {col.null_count} empty rows")
        values = col.flatten()
    else:
        values = col
    if len(values) != rows * width:
        raise ValueError(
            f"{where}: column {key!r} holds {len(values)} values for {rows} rows, expected {width} per row"
        )
    return np.asarray(values.to_numpy(zero_copy_only=False), dtype=np.float32).reshape(rows, width)


def camera_size(feature: dict[str, Any]) -> tuple[int, int]:
    """(height, width) of a camera feature; some datasets store the shape channels-first."""
    shape = [int(s) for s in feature.get("shape", [])]
    names = list(feature.get("names") or [])
    if len(shape) != 3:
        raise ValueError(f"expected a (height, width, channels) shape, got {shape}")
    if names[:1] == ["channels"] or (shape[0] == 3 and shape[2] != 3):
        return shape[1], shape[2]
    return shape[0], shape[1]


def vector_feature(feats: dict[str, Any], key: str, role: str, *, where: str) -> tuple[int, tuple[str, ...]]:
    """(width, names) of the vector feature ``key`` used as ``role`` (state/action)."""
    if key not in feats:
        vectors = sorted(k for k, ft in feats.items() if ft.get("dtype") not in CAMERA_DTYPES)
        raise ValueError(f"{where}: no feature {key!r} for the {role} (features: {vectors}); set '{role}_key'")
    shape = feats[key].get("shape") or [1]
    width = int(np.prod(shape))
    return width, feature_names(feats[key].get("names"), width, role)
