"""Write-then-rename file updates: a reader never sees a half-written file, whatever kills the writer.

Each write goes to ``<name>.tmp-<pid>`` in the same folder, is flushed and fsynced, and is renamed
over the target (atomic on POSIX). The folder is fsynced too, so a committed rename survives a power
cut, not just a killed process.
"""

from __future__ import annotations

import json
import os
from collections.abc import Callable
from pathlib import Path
from typing import Any

import pyarrow as pa
import pyarrow.parquet as pq

TMP_MARK = ".tmp-"


def _fsync_dir(path: Path) -> None:
    fd = os.open(path, os.O_RDONLY)
    try:
        os.fsync(fd)
    finally:
        os.close(fd)


def atomic_write(path: Path, write: Callable[[Path], object], *, durable: bool = True) -> None:
    """Call ``write(tmp_path)``, then move the finished file to ``path``."""
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(f"{path.name}{TMP_MARK}{os.getpid()}")
    try:
        write(tmp)
        if durable:
            with tmp.open("rb") as fh:
                os.fsync(fh.fileno())
        tmp.replace(path)
    finally:
        tmp.unlink(missing_ok=True)
    if durable:
        _fsync_dir(path.parent)


def write_json(path: Path, data: Any, *, durable: bool = True) -> None:
    text = json.dumps(data, indent=2, sort_keys=False) + "\n"
    atomic_write(path, lambda tmp: tmp.write_text(text, encoding="utf-8"), durable=durable)


def write_parquet(path: Path, table: pa.Table, *, durable: bool = True) -> None:
    atomic_write(path, lambda tmp: pq.write_table(table, tmp, compression="snappy"), durable=durable)


def is_temporary(path: Path) -> bool:
    return TMP_MARK in path.name
