"""``convert``: detect a source's format, create our dataset, append its episodes; resumable.

Resuming relies on the writer's commit protocol: an interrupted conversion leaves ``k`` committed
episodes (and at most one half-written one that the next writer deletes). Running the same command
again finds the ``k`` episodes, checks they are the first ``k`` of this source (same spec, same
lengths, same source episode numbers) and continues with episode ``k``.
"""

from __future__ import annotations

import json
import time
from pathlib import Path
from typing import Any

from tqdm import tqdm

from pilworld.data import layout
from pilworld.data.convert.aloha_hdf5 import AlohaHdf5Source
from pilworld.data.convert.base import EpisodeSource
from pilworld.data.convert.lerobot_v21 import VERSIONS as V2_VERSIONS
from pilworld.data.convert.lerobot_v21 import LeRobotV21Source
from pilworld.data.convert.lerobot_v30 import LeRobotV30Source
from pilworld.data.convert.mapping import ConvertMapping
from pilworld.data.reader import EpisodeStore, read_info
from pilworld.data.spec import CODEBASE_VERSION, DatasetSpec
from pilworld.data.video_codec import codec_settings
from pilworld.data.writer import EpisodeWriter

SOURCES: dict[str, type[EpisodeSource]] = {
    LeRobotV21Source.format_name: LeRobotV21Source,
    LeRobotV30Source.format_name: LeRobotV30Source,
    AlohaHdf5Source.format_name: AlohaHdf5Source,
}
FORMATS = ("auto", *SOURCES)
HDF5_SUFFIXES = (".hdf5", ".h5")


def detect_format(source: Path) -> str:
    """The format name of ``source``; ``ValueError`` naming it when it is none of ours."""
    if not source.exists():
        raise ValueError(f"{source}: no such file or folder")
    if source.is_file():
        if source.suffix in HDF5_SUFFIXES:
            return AlohaHdf5Source.format_name
        raise ValueError(f"{source}: unknown format (a single file must be an ALOHA .hdf5 episode)")
    if (source / layout.INFO).is_file():
        version = read_info(source).get("codebase_version")
        if version == CODEBASE_VERSION:
            return LeRobotV30Source.format_name
        if version in V2_VERSIONS:
            return LeRobotV21Source.format_name
        raise ValueError(
            f"{source / layout.INFO}: codebase_version {version!r} is not supported "
            f"(supported: {[*V2_VERSIONS, CODEBASE_VERSION]})"
        )
    if any(p.suffix in HDF5_SUFFIXES for p in source.iterdir()):
        return AlohaHdf5Source.format_name
    raise ValueError(
        f"{source}: unknown format: no {layout.INFO} (LeRobot) and no .hdf5 files (ALOHA); pass --format {FORMATS[1:]}"
    )


def open_source(source: Path, fmt: str, mapping: ConvertMapping) -> EpisodeSource:
    """The importer for ``source`` (``fmt`` may be ``"auto"``)."""
    if fmt not in FORMATS:
        raise ValueError(f"format: expected one of {list(FORMATS)}, got {fmt!r}")
    if fmt == "auto":
        fmt = detect_format(source)
    elif not source.exists():
        raise ValueError(f"{source}: no such file or folder")
    return SOURCES[fmt](source, mapping)


def _spec_difference(old: DatasetSpec, new: DatasetSpec) -> str:
    a, b = old.to_json(), new.to_json()
    return "; ".join(f"{k}: {a[k]!r} there, {b[k]!r} now" for k in a if a[k] != b.get(k))


def _already_converted(out: Path, spec: DatasetSpec, src: EpisodeSource) -> int:
    """How many episodes of ``src`` a previous run committed to ``out`` (0 for a new output)."""
    if not out.exists():
        return 0
    if not out.is_dir():
        raise ValueError(f"{out}: exists and is not a folder")
    if not (out / layout.INFO).is_file():
        # A writer killed while creating the dataset may leave meta/ only; anything else is not ours.
        if any(p.name != "meta" for p in out.iterdir()):
            raise ValueError(f"{out}: exists and is not a dataset; choose a new output folder")
        return 0
    store = EpisodeStore(out)
    if store.spec != spec:
        raise ValueError(
            f"{out}: exists with a different spec ({_spec_difference(store.spec, spec)}); "
            "resume with the same mapping and --video-mode, or choose a new output folder"
        )
    lengths = src.lengths()
    if store.num_episodes > len(lengths):
        raise ValueError(f"{out}: holds {store.num_episodes} episodes but {src.path} has {len(lengths)}")
    for j, row in enumerate(store.episodes):
        came_from = (json.loads(row["extra"]) if row.get("extra") else {}).get("converted_from")
        expected = src.provenance(j)["converted_from"]
        if int(row["length"]) != lengths[j] or came_from != expected:
            raise ValueError(
                f"{out}: episode {j} ({row['length']} frames, converted from {came_from}) is not {expected} of "
                f"{src.path} ({lengths[j]} frames); not a partial conversion of this source, choose a new output folder"
            )
    return store.num_episodes


def convert(
    source: Path,
    out: Path,
    mapping: ConvertMapping | None = None,
    video_mode: str = "h264",
    fmt: str = "auto",
    progress: bool = True,
) -> dict[str, Any]:
    """Convert ``source`` into a PiL-World dataset at ``out``; returns a JSON-able summary.

    ``fmt`` is ``"auto"`` or one of :data:`SOURCES`. When ``out`` already holds the first ``k``
    episodes of this source (an interrupted run), conversion continues with episode ``k``.
    """
    source, out = Path(source), Path(out)
    mapping = mapping or ConvertMapping()
    codec_settings(video_mode)  # an unknown mode fails before anything is read
    if out.resolve() == source.resolve() or source.resolve() in out.resolve().parents:
        raise ValueError(f"{out}: the output must not be the source or inside it")
    src = open_source(source, fmt, mapping)
    if mapping.resize is not None and video_mode != "lossless" and any(s % 2 for s in mapping.resize):
        raise ValueError(f"mapping field 'resize': {video_mode} needs an even size, got {list(mapping.resize)}")
    try:
        spec = src.spec(video_mode)
    except ValueError as err:
        raise ValueError(f"{source}: {err}") from None
    lengths = src.lengths()
    done = _already_converted(out, spec, src)

    started = time.monotonic()
    frames = 0
    with EpisodeWriter(out, spec) as writer:
        bar = tqdm(total=len(lengths), initial=done, unit="ep", desc=f"convert {source.name}", disable=not progress)
        try:
            for index, episode in enumerate(src.iter_episodes(done), start=done):
                try:
                    writer.append(episode)
                except ValueError as err:  # the episode does not fit the spec (sizes, lengths, names)
                    raise ValueError(f"{source}: episode {index}: {err}") from err
                frames += episode.length
                bar.update(1)
        finally:
            bar.close()
        total_episodes, total_frames = writer.num_episodes, writer.num_frames
    return {
        "source": str(source),
        "format": src.format_name,
        "out": str(out),
        "episodes": total_episodes,
        "frames": total_frames,
        "skipped": done,
        "converted": total_episodes - done,
        "converted_frames": frames,
        "fps": spec.fps,
        "views": {view: list(size) for view, size in spec.views.items()},
        "state_dim": spec.state_dim,
        "action_dim": spec.action_dim,
        "video_mode": video_mode,
        "seconds": round(time.monotonic() - started, 3),
    }
