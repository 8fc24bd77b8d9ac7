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
from pilworld.data.spec import CODEBASE_VERSION, DatasetSpec, spec_difference
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


def _check_resumed(out: Path, store: EpisodeStore, src: EpisodeSource, first: int, done: int) -> None:
    """Episodes ``first`` … ``first + done - 1`` of ``out`` must be the first ``done`` of ``src``."""
    lengths = src.lengths()
    if done > len(lengths):
        raise ValueError(f"{out}: holds {done} episodes of {src.path}, which has {len(lengths)}")
    rows = store.episodes
    for j in range(done):
        row = rows[first + j]
        came_from = (json.loads(row["extra"]) if row.get("extra") else {}).get("converted_from")
        expected = src.provenance(j)["converted_from"]
        if int(row["length"]) != lengths[j] or came_from != expected:
            raise ValueError(
                f"{out}: episode {first + j} ({row['length']} frames, converted from {came_from}) is not {expected} "
                f"of {src.path} ({lengths[j]} frames); not a partial conversion of this source, choose a new OUT"
            )


def _resume_point(
    out: Path, spec: DatasetSpec, src: EpisodeSource, *, append: bool
) -> tuple[int, int, list[dict[str, Any]]]:
    """Where ``src`` goes in ``out``: (its first episode there, how many of its episodes are there already,
    the sources of ``out`` with it). Resuming keys on the source (its resolved path, in ``conversion.json``),
    never on an episode index alone: another source is refused, or with ``append`` added after the others."""
    from pilworld.io.run_folder import CONVERTED, EPISODE_STORE, check_out_folder, read_marker

    held = check_out_folder(out, CONVERTED, "OUT", legacy=True)
    me = str(Path(src.path).resolve())
    total = len(src.lengths())
    entry = {"path": me, "format": src.format_name, "first_episode": 0, "episodes": total}
    if held is None:
        return 0, 0, [entry]
    store = EpisodeStore(out)
    if store.spec != spec:
        raise ValueError(
            f"{out}: exists with a different spec ({spec_difference(store.spec, spec)}); "
            "resume with the same mapping and --video-mode, or choose a new output folder"
        )
    n = store.num_episodes
    if held == EPISODE_STORE:  # converted before conversion.json: its source was not recorded
        if append:
            entry["first_episode"] = n
            return n, 0, [{"path": "", "format": "", "first_episode": 0, "episodes": n}, entry]
        _check_resumed(out, store, src, 0, n)
        return 0, n, [entry]
    marker = read_marker(out, CONVERTED) or {}
    sources = [dict(x) for x in marker.get("sources", []) if isinstance(x, dict)]
    for k, source in enumerate(sources):
        if source.get("path") != me:
            continue
        first = int(source.get("first_episode", 0))
        end = int(sources[k + 1]["first_episode"]) if k + 1 < len(sources) else n
        done = end - first
        _check_resumed(out, store, src, first, done)
        if append:
            raise ValueError(
                f"--append: {src.path} is already source {k + 1} of {out} (episodes {first}..{first + done - 1}); "
                + ("rerun without --append to resume it" if done < total else "nothing to append")
            )
        if done < total and k + 1 < len(sources):
            raise ValueError(f"{out}: {src.path} was cut short before another source was appended; choose a new OUT")
        return first, done, sources
    last = sources[-1] if sources else {}
    if not append:
        raise ValueError(
            f"{out}: holds a conversion of {last.get('path') or 'another source'} ({n} episodes); {src.path} is "
            "another source: pass --append to add its episodes after them, or choose a new OUT"
        )
    if last:
        owned = n - int(last.get("first_episode", 0))
        if owned < int(last.get("episodes", owned)):
            raise ValueError(
                f"--append: the conversion of {last.get('path')} into {out} is unfinished "
                f"({owned} of {last.get('episodes')} episodes); finish it first (rerun it without --append)"
            )
    entry["first_episode"] = n
    return n, 0, [*sources, entry]


def convert(
    source: Path,
    out: Path,
    mapping: ConvertMapping | None = None,
    video_mode: str = "h264",
    fmt: str = "auto",
    progress: bool = True,
    append: bool = False,
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
    from pilworld.io.run_folder import CONVERTED, claim

    lengths = src.lengths()
    first, done, sources = _resume_point(out, spec, src, append=append)
    if done < len(lengths):  # nothing is written for a source already converted in full
        claim(out, CONVERTED, {"video_mode": video_mode, "sources": sources})

    started = time.monotonic()
    frames = converted = 0
    with EpisodeWriter(out, spec) as writer:
        bar = tqdm(total=len(lengths), initial=done, unit="ep", desc=f"convert {source.name}", disable=not progress)
        try:
            for index, episode in enumerate(src.iter_episodes(done), start=done):
                try:
                    writer.append(episode)
                except ValueError as err:  # the episode does not fit the spec (sizes, lengths, names)
                    raise ValueError(f"{source}: episode {index}: {err}") from err
                frames += episode.length
                converted += 1
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
        "converted": converted,
        "first_episode": first,
        "converted_frames": frames,
        "fps": spec.fps,
        "views": {view: list(size) for view, size in spec.views.items()},
        "state_dim": spec.state_dim,
        "action_dim": spec.action_dim,
        "video_mode": video_mode,
        "seconds": round(time.monotonic() - started, 3),
    }
