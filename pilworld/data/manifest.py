"""File manifests: the size and sha256 of every file a dataset committed, so a lost or damaged file is noticed.

Two manifests, both written by :class:`~pilworld.data.writer.EpisodeWriter`:

- **per episode**, the ``manifest`` column of its ``meta/episodes`` row (a JSON object
  ``{relative path: {"size": bytes, "sha256": hex}}`` of its data parquet and its mp4s). It is written in
  the same atomic rename as the row itself — the commit point — so a committed episode always has the
  manifest of exactly the files it committed.
- **per dataset**, ``meta/manifest.json``: the same for the metadata files episodes cannot describe
  themselves (the ``meta/episodes`` tables holding those manifests, ``meta/tasks.parquet``), rewritten
  after each commit (step 4). A writer killed between the commit and this file leaves it one episode
  behind; the next writer to open the dataset rewrites it.

Datasets written before manifests existed (or by LeRobot) have neither; they stay readable and
``pilworld data verify`` reports them as "no manifest", checking what it can without one.
"""

from __future__ import annotations

import hashlib
import json
from dataclasses import dataclass
from pathlib import Path
from typing import Any

MANIFEST_COLUMN = "manifest"
META_MANIFEST = "meta/manifest.json"
_BLOCK = 1 << 20


@dataclass(frozen=True)
class FileEntry:
    size: int
    sha256: str

    def to_json(self) -> dict[str, Any]:
        return {"size": self.size, "sha256": self.sha256}


def sha256_file(path: Path) -> str:
    h = hashlib.sha256()
    with path.open("rb") as fh:
        while block := fh.read(_BLOCK):
            h.update(block)
    return h.hexdigest()


def entry(path: Path) -> FileEntry:
    return FileEntry(size=path.stat().st_size, sha256=sha256_file(path))


def manifest_json(root: Path, paths: list[Path]) -> str:
    """The manifest of ``paths`` (files under ``root``) as the JSON text stored in an episodes row."""
    return json.dumps({p.relative_to(root).as_posix(): entry(p).to_json() for p in paths}, sort_keys=True)


def parse_manifest(text: object, *, source: str) -> dict[str, FileEntry] | None:
    """A stored manifest; None when there is none (an older dataset). Raises ValueError when it is garbled."""
    if text is None or text == "":
        return None
    try:
        raw = json.loads(str(text))
        return {str(k): FileEntry(size=int(v["size"]), sha256=str(v["sha256"])) for k, v in raw.items()}
    except (ValueError, TypeError, KeyError, AttributeError) as err:
        raise ValueError(f"{source}: manifest is not valid ({err})") from None


@dataclass(frozen=True)
class FileProblem:
    """One file that does not match its manifest entry."""

    path: str  # relative to the dataset root
    kind: str  # missing | size | hash | unreadable | truncated
    detail: str

    def describe(self) -> str:
        return f"file {self.path} {self.detail}"


def check_file(root: Path, rel: str, want: FileEntry, *, hash_files: bool) -> FileProblem | None:
    """Compare one file with its entry: existence and size always, the sha256 only with ``hash_files``."""
    path = root / rel
    if not path.is_file():
        return FileProblem(rel, "missing", "missing")
    size = path.stat().st_size
    if size != want.size:
        return FileProblem(rel, "size", f"is {size} bytes, manifest says {want.size}")
    if hash_files and sha256_file(path) != want.sha256:
        return FileProblem(rel, "hash", "content differs from its sha256 in the manifest")
    return None


def read_meta_manifest(root: Path, name: str = META_MANIFEST) -> dict[str, FileEntry] | None:
    path = root / name
    if not path.is_file():
        return None
    return parse_manifest(path.read_text(encoding="utf-8") or None, source=str(path))


def meta_manifest_text(root: Path, paths: list[Path]) -> dict[str, Any]:
    out: dict[str, Any] = json.loads(manifest_json(root, [p for p in paths if p.is_file()]))
    return out
