"""A resumed paired / imagined-only run checks what it already stored, and redoes the branches it lost.

Skipping every stored branch would trust files a full disk, a stopped copy or a deleted folder damaged;
so before it skips anything a resume runs the cheap check of :func:`pilworld.data.verify.check_dataset`
(each episode's files exist with their manifest size). A damaged branch is taken out of the done set,
announced on stderr in one line, and run again into its old episode slot (:meth:`EpisodeWriter.replace`):
every branch is seeded, so the redone episode is the one the interrupted run wrote, with the same length
and index. A paired run's starts/ folder is checked the same way, and a damaged start recorded again.
"""

from __future__ import annotations

import json
import sys
from collections.abc import Callable
from pathlib import Path
from typing import Any

from pilworld.data.backup import restore_tables
from pilworld.data.reader import DatasetError, EpisodeStore
from pilworld.data.verify import Problem, check_dataset

Branch = tuple[str, str]  # (pair id, origin)


def _stderr(line: str) -> None:
    print(line, file=sys.stderr, flush=True)


def _damaged(root: Path) -> list[tuple[int, dict[str, Any], Problem]]:
    """(index, episodes-table row, first problem) of each damaged episode of the dataset at ``root``."""
    if not (root / "meta" / "info.json").is_file():
        return []
    check = check_dataset(root, hash_files=True)
    tables = check.table_problems()
    if tables:
        raise DatasetError(
            f"{root}: {tables[0].describe()}; the run's own tables are damaged, so its episodes cannot be "
            f"redone one by one (`pilworld data verify {root}` lists every problem)"
        )
    damaged = check.damaged_episodes()
    rows = EpisodeStore(root).episodes if damaged else []
    return [(index, rows[index], problem) for index, problem in sorted(damaged.items())]


def restore_run(root: Path, *, say: Callable[[str], None] = _stderr) -> None:
    """Put back the damaged tables of the run at ``root`` (its dataset, its starts/) from their backups,
    one line each (:mod:`pilworld.data.backup`); before anything reads them."""
    for folder in (root, root / "starts"):
        if (folder / "meta").is_dir():
            restore_tables(folder, say=say)


def _extra(row: dict[str, Any]) -> dict[str, Any]:
    extra: dict[str, Any] = json.loads(row.get("extra") or "{}")
    return extra


def damaged_branches(root: Path, *, say: Callable[[str], None] = _stderr) -> dict[Branch, int]:
    """(pair id, origin) → episode index of every stored branch of the run at ``root`` whose files are damaged.

    Says one line per damaged episode. Raises :class:`DatasetError` when the run's own tables (episodes
    table, info, outcomes) are damaged: which episode is which cannot then be known, so nothing is redone.
    """
    out: dict[Branch, int] = {}
    for index, row, problem in _damaged(root):
        pair, origin = _extra(row).get("pair"), str(row.get("origin"))
        if pair is None:  # not a branch of this run (never written by it): nothing to redo it from
            raise DatasetError(f"{root}: episode {index} is damaged ({problem.path} {problem.detail}) and is no branch")
        say(f"episode {index} ({pair}, {origin}): {problem.path} {problem.detail} — redoing")
        out[(str(pair), origin)] = index
    return out


def damaged_starts(root: Path, *, say: Callable[[str], None] = _stderr) -> dict[tuple[str, str], int]:
    """(start id, checkpoint) → episode index of every stored start in the starts folder ``root`` that is damaged.

    Says one line per damaged start; :meth:`StartsWriter.redo` takes them back, and its ``add`` rewrites them.
    """
    out: dict[tuple[str, str], int] = {}
    for index, row, problem in _damaged(root):
        extra = _extra(row)
        if "start_id" not in extra:
            raise DatasetError(f"{root}: episode {index} is damaged ({problem.path} {problem.detail}) and is no start")
        key = (str(extra["start_id"]), str(extra.get("start_checkpoint", "")))
        who = key[0] + (f", {key[1]}" if key[1] else "")
        say(f"{root.name} episode {index} ({who}): {problem.path} {problem.detail} — redoing")
        out[key] = index
    return out


def take_out(done: dict[str, set[str]], redo: dict[Branch, int]) -> None:
    """Remove the branches to redo from ``done`` (pair id → stored origins)."""
    for pair, origin in redo:
        done.get(pair, set()).discard(origin)
