"""The cache's worker pool: clean worker processes, the caller's environment, a dead worker is an error.

A forked child inherits every lock as some thread of the parent held it at the fork, so a training run started
from a process that ran threaded code (a test worker, a notebook) could block forever; a worker killed for memory
left ``multiprocessing.Pool`` waiting forever for its clip. These tests fail (rather than hang: each wait is
bounded) if the pool forks the caller or loses a worker silently.
"""

from __future__ import annotations

import os
import threading
from concurrent.futures.process import BrokenProcessPool
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from pilworld.config.rig import RigConfig
from pilworld.data.reader import EpisodeStore
from pilworld.world_model.composite.cache import CacheSpec, _fill, build_cache

from ..training.synthetic_data import write_dataset

_HELD = threading.Lock()  # held by a thread of the test process while the pool starts (a fork would copy it held)
_STATE: dict[str, Any] = {}


def _init(tag: str) -> None:
    if not _HELD.acquire(timeout=10):  # a forked child would wait on the copy of the held lock; bounded here
        raise RuntimeError("the worker inherited a lock held in the parent")
    _STATE["tag"] = tag


def _build(job: tuple[int, int, list[int]]) -> tuple[int, Any, Any]:
    row, clip, _ = job
    env = os.environ.get("PILWORLD_TEST_POOL", "")
    return row, np.full((2, 3), clip, np.int64), np.array([[len(env), len(_STATE["tag"])]] * 2, np.int64)


def _die(job: tuple[int, int, list[int]]) -> tuple[int, Any]:
    os._exit(3)  # as a worker killed for memory or crashed in native code


def _arrays(tmp: Path, n: int) -> list[Any]:
    return [
        np.lib.format.open_memmap(tmp / "a.npy", "w+", np.int64, (n, 3)),
        np.lib.format.open_memmap(tmp / "b.npy", "w+", np.int64, (n, 2)),
    ]


@pytest.mark.timeout(120)
def test_workers_start_clean_and_see_the_callers_environment(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    jobs = [(r, 10 + r, [0]) for r in range(5)]
    release = threading.Event()

    def hold() -> None:
        with _HELD:
            release.wait(30)

    holder = threading.Thread(target=hold, daemon=True)
    holder.start()
    try:
        for value in ("x", "longer"):  # set after the first pool started: the second must see the new value
            monkeypatch.setenv("PILWORLD_TEST_POOL", value)
            arrays = _arrays(tmp_path, 10)
            _fill(arrays, _build, _init, ("tag",), jobs, 2, workers=2, chunksize=1, desc="test", progress=False)
            np.testing.assert_array_equal(np.load(tmp_path / "a.npy")[:, 0], np.repeat(10 + np.arange(5), 2))
            np.testing.assert_array_equal(np.load(tmp_path / "b.npy"), [[len(value), 3]] * 10)
    finally:
        release.set()
        holder.join()


@pytest.mark.timeout(120)
def test_a_worker_that_dies_is_an_error_not_a_hang(tmp_path: Path) -> None:
    arrays = _arrays(tmp_path, 4)[:1]
    with pytest.raises(BrokenProcessPool):
        _fill(
            arrays,
            _die,
            _init,
            ("tag",),
            [(0, 0, [0]), (1, 1, [0])],
            2,
            workers=2,
            chunksize=1,
            desc="t",
            progress=False,
        )


@pytest.mark.timeout(180)
def test_the_cache_builds_after_this_process_decoded_video(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, rig32: RigConfig
) -> None:
    # The case that hung: a process that decoded video (PyAV's FFmpeg threads) then forked the cache's workers.
    monkeypatch.setenv("PILWORLD_CACHE", str(tmp_path / "clips"))
    data = write_dataset(tmp_path / "ds")
    store = EpisodeStore(data)
    assert store.load(0).images  # decode every view of an episode here, in the test process
    spec = CacheSpec(str(data), "unused", size=32, frames_per_clip=2, max_clips=4)
    out = build_cache(spec, tmp_path / "cache", rig=rig32, workers=2, progress=False)
    assert np.load(out / "targets.npy").any()
