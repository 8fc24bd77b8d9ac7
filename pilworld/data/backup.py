"""A second copy of a dataset's own tables, so a resumed run can restore any one of them that was damaged.

An episode's files can be written again from its seed; the files that say which episode is which cannot:
the ``meta/episodes`` tables (each row holds its episode's manifest), ``info.json``, ``tasks.parquet``,
``stats.json``, ``pilworld.json``, ``manifest.json``, the outcomes table and its manifest, and a run's JSON
settings. The writers copy each of them to ``meta/backup/`` (same relative path) after writing it, the
manifest last, so the backup is always one whole, consistent generation.

:func:`restore_tables` (run by a resumed run before it checks its episodes) compares every table with the
manifest (``meta/manifest.json``, or its backup when that is the damaged one) and, for a table that does
not match, puts its backup back. A table that does not match yet reads, and holds every row of its backup
and more, is not damage: it is a commit the manifest had not caught up with when a writer was killed
(the writer's next open rewrites the manifest), and it is kept. A damaged backup is copied again from the
intact table. ``pilworld data verify`` checks the backups like every other file.
"""

from __future__ import annotations

import json
import shutil
from collections.abc import Callable, Iterable
from dataclasses import dataclass
from pathlib import Path

import pyarrow.parquet as pq

from pilworld.data import layout
from pilworld.data.manifest import META_MANIFEST, FileEntry, FileProblem, check_file, parse_manifest, sha256_file
from pilworld.data.reader import DatasetError
from pilworld.io.atomic import atomic_write

BACKUP_DIR = "meta/backup"
OUTCOMES_MANIFEST = "meta/outcomes_manifest.json"
# Each manifest and the tables it covers (the outcomes table keeps a manifest of its own).
MANIFESTS = (META_MANIFEST, OUTCOMES_MANIFEST)
# JSON settings a run writes once beside its dataset; checked by reading (they have no manifest).
SIDECARS = (
    "paired_config.json",
    "imagine_config.json",
    "policy_metadata.json",
    "starts.json",
    "paired_timings.jsonl",
    "imagine_timings.jsonl",
)


class TableLostError(DatasetError):
    """A table and its backup are both damaged: which episode is which cannot be known."""


def backup_path(root: Path, rel: str) -> Path:
    return root / BACKUP_DIR / rel


def back_up(root: Path, rels: Iterable[str], *, durable: bool = True) -> None:
    """Copy each existing file ``root/rel`` to its backup (atomically: a killed copy leaves the old backup)."""
    for rel in rels:
        if (root / rel).is_file():
            _copy(root / rel, backup_path(root, rel), durable=durable)


@dataclass(frozen=True)
class Repair:
    """One file :func:`restore_tables` put back."""

    path: str  # relative to the dataset root
    detail: str  # what was wrong with it

    def describe(self) -> str:
        return f"{self.path} {self.detail} — restored from {BACKUP_DIR}/{self.path}"


def _manifest(path: Path) -> dict[str, FileEntry] | None:
    """A manifest file's entries; None when it is missing or garbled."""
    if not path.is_file():
        return None
    try:
        return parse_manifest(path.read_text(encoding="utf-8") or None, source=str(path))
    except (ValueError, UnicodeDecodeError):
        return None


def _rows(path: Path) -> list[dict[str, object]] | None:
    try:
        rows: list[dict[str, object]] = pq.read_table(path).to_pylist()
    except Exception:
        return None
    return rows


def _is_later_commit(primary: Path, backup: Path) -> bool:
    """The primary table reads and holds every row of its backup, and more: a commit, not damage."""
    if primary.suffix != ".parquet" or not backup.is_file():
        return False
    new, old = _rows(primary), _rows(backup)
    if new is None or old is None or len(new) <= len(old):
        return False
    keys = [json.dumps(r, sort_keys=True, default=str) for r in new]
    return all(json.dumps(r, sort_keys=True, default=str) in keys for r in old)


def _copy(src: Path, dst: Path, *, durable: bool = True) -> None:
    atomic_write(dst, lambda tmp: shutil.copyfile(src, tmp), durable=durable)


def _restore_group(root: Path, manifest_rel: str, say: Callable[[str], None]) -> list[Repair]:
    """Check the tables one manifest covers, and their backups; put back what is damaged."""
    bdir = root / BACKUP_DIR
    prim, back = _manifest(root / manifest_rel), _manifest(bdir / manifest_rel)
    if prim is None and back is None:
        if (root / manifest_rel).is_file() or (bdir / manifest_rel).is_file():
            raise TableLostError(f"{root}: {manifest_rel} and its backup are both unreadable")
        return []  # nothing written yet (a dataset with no verdicts has no outcomes table)

    def matches(base: Path, entries: dict[str, FileEntry]) -> int:
        return sum(check_file(base, rel, e, hash_files=True) is None for rel, e in entries.items())

    # The manifest the primary tables agree with best: a damaged manifest still parsing loses to its backup.
    chosen = max((m for m in (prim, back) if m is not None), key=lambda m: matches(root, m))
    repairs: list[Repair] = []
    later_commit = False
    for rel, entry in sorted(chosen.items(), key=lambda kv: not kv[0].startswith(layout.EPISODES_DIR)):
        bad = check_file(root, rel, entry, hash_files=True)
        backup_bad = check_file(bdir, rel, entry, hash_files=True)
        if bad is None:
            if backup_bad is not None:
                _copy(root / rel, bdir / rel)
            continue
        if _is_later_commit(root / rel, bdir / rel) or (later_commit and _readable(root / rel)):
            later_commit = True  # info/stats/tasks written by that same commit are kept with it
            continue
        if backup_bad is not None:
            raise TableLostError(
                f"{root}: {rel} {bad.detail}, and its backup {BACKUP_DIR}/{rel} {backup_bad.detail}; "
                "which episode is which cannot be recovered"
            )
        _copy(bdir / rel, root / rel)
        repairs.append(Repair(rel, bad.detail))
    if not later_commit:
        mbad = prim is None or prim != chosen
        if mbad and (bdir / manifest_rel).is_file() and back == chosen:
            _copy(bdir / manifest_rel, root / manifest_rel)
            repairs.append(Repair(manifest_rel, "missing" if not (root / manifest_rel).is_file() else "is damaged"))
        elif back != chosen and (root / manifest_rel).is_file():
            _copy(root / manifest_rel, bdir / manifest_rel)
    for r in repairs:
        say(r.describe())
    return repairs


def _readable(path: Path) -> bool:
    if not path.is_file():
        return False
    if path.suffix == ".parquet":
        return _rows(path) is not None
    try:
        text = path.read_text(encoding="utf-8")
        for line in text.splitlines() if path.suffix == ".jsonl" else [text]:
            json.loads(line)
    except (ValueError, UnicodeDecodeError):
        return False
    return True


def _restore_sidecars(root: Path, say: Callable[[str], None]) -> list[Repair]:
    repairs: list[Repair] = []
    for rel in SIDECARS:
        path, copy = root / rel, backup_path(root, rel)
        if not copy.is_file():
            if path.is_file():
                _copy(path, copy)
            continue
        if _readable(path):
            have, kept = path.read_bytes(), copy.read_bytes()
            if have == kept:
                continue
            if path.suffix == ".jsonl" and len(kept) > len(have) and kept.startswith(have):
                _copy(copy, path)  # cut short at a line's end: still reads, but lines are missing
                repairs.append(Repair(rel, "is cut short"))
            else:
                _copy(path, copy)  # a writer killed before its backup: the file is newer
            continue
        if not _readable(copy):
            raise TableLostError(f"{root}: {rel} and its backup are both unreadable")
        _copy(copy, path)
        repairs.append(Repair(rel, "missing" if not path.exists() else "does not read as JSON"))
    for r in repairs:
        say(r.describe())
    return repairs


def restore_tables(root: str | Path, *, say: Callable[[str], None]) -> list[Repair]:
    """Put back every damaged table of the dataset at ``root`` from its backup; says one line for each.

    Raises :class:`TableLostError` when a table and its backup are both damaged."""
    root = Path(root)
    if not (root / BACKUP_DIR).is_dir():
        return []  # written before backups existed: nothing to restore from
    repairs = _restore_sidecars(root, say)
    for manifest_rel in MANIFESTS:
        repairs += _restore_group(root, manifest_rel, say)
    return repairs


def _same_as_primary(root: Path, rel: str, *, hash_files: bool) -> list[FileProblem]:
    """A file no manifest covers (a manifest, a JSON setting) and its backup: both there, readable, equal."""
    copy, primary, name = backup_path(root, rel), root / rel, f"{BACKUP_DIR}/{rel}"
    if not primary.is_file():
        return [FileProblem(rel, "missing", "missing")]
    if not _readable(primary):
        return [FileProblem(rel, "unreadable", "does not read as JSON")]
    if not copy.is_file():
        return [FileProblem(name, "missing", "missing")]
    if copy.stat().st_size != primary.stat().st_size:
        return [FileProblem(name, "size", f"is {copy.stat().st_size} bytes, {rel} is {primary.stat().st_size}")]
    if hash_files and sha256_file(copy) != sha256_file(primary):
        return [FileProblem(name, "hash", f"content differs from {rel}")]
    return []


def backup_problems(root: str | Path, *, hash_files: bool) -> list[FileProblem]:
    """Every backup copy that is missing or differs from what it backs up (``pilworld data verify``)."""
    root = Path(root)
    bdir = root / BACKUP_DIR
    if not bdir.is_dir():
        return []  # a dataset written before backups existed
    out: list[FileProblem] = []
    for manifest_rel in MANIFESTS:
        entries = _manifest(root / manifest_rel) or _manifest(bdir / manifest_rel)
        if entries is None:
            continue  # none written yet, or both unreadable (reported by the caller's manifest check)
        for rel, entry in sorted(entries.items()):
            bad = check_file(bdir, rel, entry, hash_files=hash_files)
            if bad is not None:
                out.append(FileProblem(f"{BACKUP_DIR}/{rel}", bad.kind, bad.detail))
        if (root / manifest_rel).is_file() and _manifest(root / manifest_rel) is None:
            continue  # a garbled manifest: the caller's own check names it
        out += _same_as_primary(root, manifest_rel, hash_files=hash_files)
    for rel in SIDECARS:
        if (root / rel).is_file() or backup_path(root, rel).is_file():
            out += _same_as_primary(root, rel, hash_files=hash_files)
    return out
