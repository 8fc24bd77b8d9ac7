"""Simulation across processes: one connected robot per worker and task, and an ordered/unordered map.

Workers are *spawned*: a forked child would inherit the parent's OpenGL (EGL) state. Each worker
keeps one connected ``SimRobot`` per (rig, task, appearance) for all its jobs, since connecting costs ~0.2 s.
"""

from __future__ import annotations

import multiprocessing as mp
import os
from collections.abc import Callable, Iterator, Sequence
from typing import TYPE_CHECKING, Any, TypeVar

if TYPE_CHECKING:
    from simrig.tasks import Task

T = TypeVar("T")
R = TypeVar("R")

_ROBOTS: dict[tuple[str, str, str], Any] = {}


def worker_robot(rig_path: str, task: str | Task, appearance: str = "flat") -> Any:
    """This process's connected ``SimRobot`` for ``(rig_path, task, appearance)``, made on first use.

    ``task`` is a packaged task's name, a task file's path or a loaded task; robots are kept per task
    file content (:attr:`Task.digest`), so an edited file gets a new scene."""
    from simrig.robot import SimRobot
    from simrig.tasks import load_task

    loaded = load_task(task)
    key = (rig_path, loaded.digest, appearance)
    if key not in _ROBOTS:
        robot = SimRobot(rig_path, loaded, appearance=appearance)
        robot.connect()
        _ROBOTS[key] = robot
    return _ROBOTS[key]


def worker_count(requested: int | None, jobs: int) -> int:
    """``requested`` processes (default: CPUs), never more than there are jobs, at least one."""
    return max(1, min(requested or os.cpu_count() or 1, jobs))


def process_map(
    fn: Callable[[T], R], items: Sequence[T], workers: int, *, ordered: bool = True, chunksize: int = 1
) -> Iterator[R]:
    """``fn`` over ``items`` in ``workers`` spawned processes (inline when 1), results as they come.

    ``ordered`` yields in input order; otherwise in completion order. Leaving the iterator early
    (an error, Ctrl-C) terminates the pool.
    """
    if workers <= 1:
        yield from map(fn, items)
        return
    with mp.get_context("spawn").Pool(workers) as pool:
        if ordered:
            yield from pool.imap(fn, items, chunksize)
        else:
            yield from pool.imap_unordered(fn, items, chunksize)
