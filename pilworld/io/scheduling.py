"""Keep video encoders from making this process real-time.

SVT-AV1 (FFmpeg's ``libsvtav1``, our ``av1`` video mode) puts the thread that opens an encoder, and the ~40
threads it starts, under ``SCHED_FIFO`` priority 99 when the process runs as root (a container, a CI
machine, a robot PC). Seen here: after the first AV1 episode a test process was FIFO 99, and every process
it started after that inherited the policy. A CPU-bound FIFO thread never yields to another of the same
priority and preempts every normal one, so this starved the process that started it, a fake rig's servo
loops and its controllers (watchdog stops), and on a real rig it would starve the arms' servo processes
while an episode is written.

:class:`RealTimeGuard` remembers which threads of this process were real-time when it was made, and
:meth:`RealTimeGuard.restore` puts every thread that became real-time since then back under ``SCHED_OTHER``.
Encoders call it right after their first frame, when the encoder threads exist.
"""

from __future__ import annotations

import os
from pathlib import Path

_TASKS = Path("/proc/self/task")
_REAL_TIME = tuple(getattr(os, name) for name in ("SCHED_FIFO", "SCHED_RR") if hasattr(os, name))


def real_time_threads() -> set[int]:
    """Thread ids of this process under a real-time policy (empty where Linux's /proc is missing)."""
    if not _REAL_TIME or not _TASKS.is_dir():
        return set()
    found: set[int] = set()
    for entry in _TASKS.iterdir():
        try:
            if os.sched_getscheduler(int(entry.name)) in _REAL_TIME:
                found.add(int(entry.name))
        except (OSError, ValueError):  # the thread ended between listing and asking
            continue
    return found


class RealTimeGuard:
    """Undo real-time scheduling that a library gave this process's threads after the guard was made."""

    def __init__(self) -> None:
        self._before = real_time_threads()

    def restore(self) -> int:
        """Every thread that became real-time since the guard was made goes back to ``SCHED_OTHER``;
        returns how many did."""
        if not _REAL_TIME:
            return 0
        restored = 0
        for tid in real_time_threads() - self._before:
            try:
                os.sched_setscheduler(tid, os.SCHED_OTHER, os.sched_param(0))
                restored += 1
            except OSError:  # ended meanwhile
                continue
        return restored
