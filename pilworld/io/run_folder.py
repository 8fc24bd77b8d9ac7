"""What made a run folder, and output paths checked before the first byte is written.

Every command that writes a folder leaves one marker of its kind at the folder's top, holding the
command's settings; most kinds had one already (``paired_config.json``, ``imagine_config.json``,
``starts.json``, ``train_config.json`` / ``settings.json``), ``sim collect`` and ``data convert`` write
``collection.json`` and ``conversion.json``. Before it writes anything a command calls
:func:`check_out_folder`: ``--out`` must be absent, empty, or a folder of the command's own kind
(resumed). A folder another command made is refused with one line naming what it holds and what
made it, so no command appends to another's run. A dataset from before the markers (an episode store
with no marker) is taken only by the commands that could have made it (``legacy``).

:func:`check_out_file` does the same for single-file outputs (PNG, MP4, HTML): a path the file
system can encode, not a folder, in a folder that exists and is writable.
"""

from __future__ import annotations

import json
import os
from collections.abc import Collection
from pathlib import Path
from typing import Any

PAIRED = "paired run"
IMAGINED = "imagined-only run"
STARTS = "starts folder"
COLLECTION = "collection"
CONVERTED = "converted dataset"
TRAINING = "training run"
JUDGE = "judge"
EPISODE_STORE = "episode store"  # a dataset with no marker: made before the markers, or by hand

MARKERS: dict[str, str] = {
    "paired_config.json": PAIRED,
    "imagine_config.json": IMAGINED,
    "starts.json": STARTS,
    "collection.json": COLLECTION,
    "conversion.json": CONVERTED,
    "train_config.json": TRAINING,
    "settings.json": TRAINING,  # pilworld train composite
    "judge.json": JUDGE,
}
MARKER_OF: dict[str, str] = {
    PAIRED: "paired_config.json",
    IMAGINED: "imagine_config.json",
    STARTS: "starts.json",
    COLLECTION: "collection.json",
    CONVERTED: "conversion.json",
    TRAINING: "train_config.json",
    JUDGE: "judge.json",
}
MADE_BY: dict[str, str] = {
    PAIRED: "pilworld paired run",
    IMAGINED: "pilworld imagine",
    STARTS: "pilworld paired record-starts",
    COLLECTION: "pilworld sim collect",
    CONVERTED: "pilworld data convert",
    TRAINING: "pilworld train",
    JUDGE: "pilworld judge train",
}
# What a writer killed while creating a folder may leave (no marker yet): taken as empty.
_CREATION_LEFTOVERS = {"meta"}


def check_path_text(path: str | os.PathLike[str], flag: str) -> None:
    """Refuse a path the file system cannot be handed as text (a byte that is not UTF-8): one line, no crash."""
    text = os.fspath(path)
    try:
        text.encode("utf-8")
    except UnicodeEncodeError:
        shown = text.encode("utf-8", "surrogateescape").decode("utf-8", "backslashreplace")
        raise ValueError(
            f"{flag}: {shown}: the path holds a byte that is not UTF-8; choose a name without it"
        ) from None


def _first_existing(path: Path) -> Path:
    p = path.absolute()
    while not p.exists() and p != p.parent:
        p = p.parent
    return p


def check_writable_place(path: Path, flag: str, *, folder: bool = True) -> None:
    """The nearest existing folder at (``folder``) or above ``path`` must be a folder we may write into."""
    base = _first_existing(path if folder and path.exists() else path.parent)
    if not base.is_dir():
        raise ValueError(f"{flag}: {base} is a file, not a folder; {path} cannot be created")
    if not os.access(base, os.W_OK | os.X_OK) or not _can_create_in(base):
        raise ValueError(f"{flag}: {base} is not writable; {path} cannot be created")


def _can_create_in(folder: Path) -> bool:
    """Whether a file can be created in ``folder`` (tried and removed at once: ``os.access`` says yes to
    root everywhere, /proc included)."""
    import tempfile

    try:
        fd, name = tempfile.mkstemp(prefix=".pilworld-probe-", dir=folder)
    except OSError:
        return False
    os.close(fd)
    Path(name).unlink()
    return True


def kind_of(path: str | Path) -> str | None:
    """What ``path`` holds: a kind of :data:`MADE_BY`, :data:`EPISODE_STORE`, "file", "other" (a
    folder with files of no run), or None (absent, empty, or the ``meta/`` a killed writer left)."""
    root = Path(path)
    if not root.exists():
        return None
    if not root.is_dir():
        return "file"
    for marker, kind in MARKERS.items():
        if (root / marker).is_file():
            return kind
    for marker, kind in MARKERS.items():  # a deleted marker still has its backup; the resume restores it
        if (root / "meta" / "backup" / marker).is_file():
            return kind
    if (root / "meta" / "info.json").is_file():
        return EPISODE_STORE
    try:
        names = {p.name for p in root.iterdir()}
    except OSError:
        return "other"
    if names <= _CREATION_LEFTOVERS and not any((root / "meta").glob("*.json")):
        return None
    return "other"


def describe(kind: str) -> str:
    if kind in MADE_BY:
        return f"{'an' if kind[0] in 'aeiou' else 'a'} {kind} (made by `{MADE_BY[kind]}`)"
    if kind == EPISODE_STORE:
        return "an episode store no pilworld command marked as its own"
    if kind == "file":
        return "a file, not a folder"
    return "files of no pilworld run"


def check_out_folder(
    out: str | Path, kind: str, flag: str = "--out", *, legacy: bool = False, also: Collection[str] = ()
) -> str | None:
    """Refuse ``out`` unless it is absent, empty or a ``kind`` folder (or, ``legacy``, an unmarked episode
    store; or one of ``also``); returns what it holds (None: nothing yet). Writes nothing."""
    check_path_text(out, flag)
    root = Path(out)
    check_writable_place(root, flag)
    held = kind_of(root)
    if held is None or held == kind or held in also or (legacy and held == EPISODE_STORE):
        return held
    article = "an" if kind[0] in "aeiou" else "a"
    raise ValueError(
        f"{flag}: {root} holds {describe(held)}; {article} {kind} is written to a folder of its own: "
        f"choose a new or empty {flag}"
    )


def read_json(path: str | Path, what: str = "") -> Any:
    """A JSON file's value; a missing, unreadable or malformed file is one line naming it (and ``what``)."""
    p = Path(path)
    lead = f"{what}: " if what else ""
    try:
        return json.loads(p.read_bytes())
    except FileNotFoundError:
        raise ValueError(f"{lead}{p}: not found") from None
    except IsADirectoryError:
        raise ValueError(f"{lead}{p}: is a folder, not a JSON file") from None
    except (UnicodeDecodeError, json.JSONDecodeError) as err:
        detail = "empty file" if not p.stat().st_size else f"not valid JSON: {err}"
        raise ValueError(f"{lead}{p}: {detail}") from None


def read_json_object(path: str | Path, what: str = "") -> dict[str, Any]:
    """:func:`read_json` of a file that must hold a JSON object."""
    value = read_json(path, what)
    if not isinstance(value, dict):
        lead = f"{what}: " if what else ""
        raise ValueError(f"{lead}{path}: expected a JSON object, found {type(value).__name__}")
    return value


def read_marker(out: str | Path, kind: str) -> dict[str, Any] | None:
    """The settings a ``kind`` marker of ``out`` holds (None when there is none); a damaged marker is one line."""
    path = Path(out) / MARKER_OF[kind]
    if not path.is_file():
        return None
    try:
        data = json.loads(path.read_text())
    except (ValueError, UnicodeDecodeError) as err:
        raise ValueError(f"{path}: damaged marker ({err}); it says which command made {out}") from None
    if not isinstance(data, dict) or data.get("kind") != kind or not isinstance(data.get("settings"), dict):
        raise ValueError(f"{path}: damaged marker (expected a JSON object with kind {kind!r} and settings)")
    settings: dict[str, Any] = data["settings"]
    return settings


def claim(out: str | Path, kind: str, settings: dict[str, Any]) -> None:
    """Mark ``out`` as a ``kind`` folder with the command's ``settings`` (after every check passed)."""
    from pilworld.io.atomic import write_json

    root = Path(out)
    root.mkdir(parents=True, exist_ok=True)
    write_json(root / MARKER_OF[kind], {"kind": kind, "made_by": MADE_BY[kind], "settings": settings})


def check_out_file(out: str | Path, flag: str = "--out", *, suffixes: Collection[str] = ()) -> Path:
    """A single output file: encodable, of one of ``suffixes``, not a folder, its folder writable."""
    check_path_text(out, flag)
    path = Path(out)
    if suffixes and path.suffix.lower() not in suffixes:
        raise ValueError(
            f"{flag}: {path}: unsupported file type {path.suffix!r}; expected a file name ending in "
            f"{' or '.join(sorted(suffixes))}"
        )
    if path.is_dir():
        raise ValueError(f"{flag}: {path} is a folder; give a file name")
    check_writable_place(path, flag, folder=False)
    if path.exists() and not os.access(path, os.W_OK):
        raise ValueError(f"{flag}: {path} is not writable")
    return path
