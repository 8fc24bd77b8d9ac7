"""Blinded per-episode, per-view MP4s in ``RUN_DIR/.annotate_cache/``.

The dataset's own videos cannot be served: their paths and names carry the episode index, the two
branches may be stored with different settings, and a run's packed files hold several episodes.
So every (episode, view) is decoded and re-encoded once with the same settings for every episode,
with nothing but pictures in it: no container metadata, ``+bitexact`` (no muxer version tag) and the
x264 settings SEI removed from the stream. File names are an HMAC of (episode, view) under the run's
secret, so a listing of the cache reveals nothing either. ``+faststart`` puts the index first, which
lets a browser start playing and seeking (with Range requests) before the whole file arrived.
"""

from __future__ import annotations

import os
import threading
from pathlib import Path

import av
import av.bitstream
import numpy as np
from numpy.typing import NDArray

from pilworld.annotate.store import AnnotationStore
from pilworld.data.reader import EpisodeStore
from pilworld.io.video import write_mp4

CACHE_DIR = ".annotate_cache"
CRF = 20  # visually clean at 128 px; judges look for small artefacts
KEYFRAME_EVERY = 10  # short GOPs: scrubbing to any frame decodes at most this many
ENCODING = 2  # part of every cache file name: bump when the encoding changes, so stale files are never served


def _strip(src_path: Path, path: Path) -> None:
    """Remux ``src_path`` without SEI units (x264 writes its version and settings there) and with no metadata.

    A second pass because the filter copies its input stream's parameters when it is made: on an
    encoder stream that has not produced a packet yet they are PyAV's defaults (640×480), which then
    end up in the file; a stream read back from a file has the true ones from the start.
    """
    options = {"movflags": "+faststart", "fflags": "+bitexact"}
    with av.open(str(src_path)) as src, av.open(str(path), mode="w", format="mp4", options=options) as dst:
        dst.metadata.clear()
        ins = src.streams.video[0]
        out = dst.add_stream_from_template(ins)
        bsf = av.bitstream.BitStreamFilterContext("filter_units=remove_types=6", ins, out)
        for packet in src.demux(ins):
            for filtered in bsf.filter(packet if packet.size else None):  # the last, empty packet flushes
                filtered.stream = out
                dst.mux(filtered)


def encode_blinded(frames: NDArray[np.uint8], path: Path, fps: float) -> None:
    """H.264 yuv420p MP4 of RGB ``frames`` (N, H, W, 3) with no metadata; odd sizes padded by a black pixel."""
    raw = path.with_name(path.name + ".raw.mp4")
    try:
        write_mp4(frames, raw, fps, CRF, keyframe_every=KEYFRAME_EVERY, bitexact=True)
        _strip(raw, path)
    finally:
        raw.unlink(missing_ok=True)


class MediaCache:
    """Encodes on first request; concurrent requests for one file wait for the one encoder."""

    def __init__(self, run_dir: Path, dataset: EpisodeStore, store: AnnotationStore) -> None:
        self.dir = run_dir / CACHE_DIR
        self.dataset = dataset
        self.store = store
        self._locks: dict[str, threading.Lock] = {}
        self._guard = threading.Lock()

    def path(self, episode: int, view: str) -> Path:
        return self.dir / f"{self.store.derive(f'media:v{ENCODING}:{episode}:{view}')[:32]}.mp4"

    def get(self, episode: int, view: str) -> Path:
        """The blinded MP4 of one episode's view, encoding it now if needed."""
        path = self.path(episode, view)
        if path.is_file():
            return path
        with self._guard:
            lock = self._locks.setdefault(path.name, threading.Lock())
        with lock:
            if not path.is_file():
                self.dir.mkdir(parents=True, exist_ok=True)
                frames = self.dataset.frames(episode, view)
                tmp = path.with_name(f".{path.name}.{os.getpid()}.{threading.get_ident()}.tmp")
                try:
                    encode_blinded(frames, tmp, float(self.dataset.fps))
                    tmp.replace(path)  # atomic: a killed server never leaves a half file under the real name
                finally:
                    tmp.unlink(missing_ok=True)
        return path

    def warm(self, episodes: list[int], views: list[str], stop: threading.Event | None = None) -> None:
        """Encode ahead of the judges (the CLI runs this in a background thread)."""
        for e in episodes:
            for v in views:
                if stop is not None and stop.is_set():
                    return
                self.get(e, v)
