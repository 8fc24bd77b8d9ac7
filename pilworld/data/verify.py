"""``pilworld data verify``: is every file a dataset (or a paired / imagined-only run) committed still there, whole?

Each committed episode carries a manifest of its files (size and sha256, :mod:`pilworld.data.manifest`);
the dataset's own metadata files are in ``meta/manifest.json``. Two depths of check:

- **cheap** (``hash_files=False``): every file exists with its manifest size; the episodes tables read.
  This is what ``pilworld data info`` and a resumed run do: it costs a ``stat`` per file, and it catches
  what actually happens to runs — a file deleted, or cut short by a full disk or a copy that stopped.
- **full** (``hash_files=True``, ``pilworld data verify``): also every file's sha256, which reads every
  byte — it catches bytes changed in place (bit rot, a bad copy of the same size).

Episodes without a manifest (datasets written before manifests, or by LeRobot) are counted as "no
manifest", not as damage; their files are still checked for presence and structure (a parquet's footer
and row count, an mp4's box structure), which finds a truncated video without decoding it.

A run folder is checked as every dataset in it (the run's own, its ``starts/``) plus the run's sidecar
files: the outcomes table must read and name only existing episodes, the JSON settings files must parse.
"""

from __future__ import annotations

import json
from collections.abc import Callable
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

from pilworld.data import layout
from pilworld.data.backup import OUTCOMES_MANIFEST, backup_problems
from pilworld.data.file_checks import mp4_problem, parquet_problem
from pilworld.data.manifest import (
    MANIFEST_COLUMN,
    META_MANIFEST,
    FileEntry,
    check_file,
    parse_manifest,
    read_meta_manifest,
)
from pilworld.data.reader import DatasetError, EpisodeStore, read_info

# JSON sidecars a run folder may hold, beside its dataset(s)
RUN_JSON = (
    "paired_config.json",
    "imagine_config.json",
    "policy_metadata.json",
    "paired_timings.jsonl",
    "imagine_timings.jsonl",
    "starts/starts.json",
)
STARTS_DIR = "starts"


@dataclass(frozen=True)
class Problem:
    """One damaged file. ``episode`` is the episode it belongs to (None: a file of the whole dataset)."""

    dataset: str  # the dataset's folder relative to the checked path ("." = the path itself)
    path: str  # the file, relative to the dataset
    kind: str  # missing | size | hash | unreadable | truncated | count
    detail: str
    episode: int | None = None

    def describe(self) -> str:
        where = self.path if self.dataset == "." else f"{self.dataset}/{self.path}"
        who = f"episode {self.episode}: " if self.episode is not None else ""
        return f"{who}{where} {self.detail}"


@dataclass
class DatasetCheck:
    """What checking one dataset found."""

    root: Path
    episodes: int = 0
    files: int = 0
    no_manifest: int = 0  # episodes written without a manifest
    problems: list[Problem] = field(default_factory=list)

    def damaged_episodes(self) -> dict[int, Problem]:
        """Episode index → its first problem."""
        out: dict[int, Problem] = {}
        for p in self.problems:
            if p.episode is not None:
                out.setdefault(p.episode, p)
        return out

    def table_problems(self) -> list[Problem]:
        """Problems of the dataset's own files (episodes tables, info, tasks)."""
        return [p for p in self.problems if p.episode is None]


def is_dataset(root: Path) -> bool:
    """A dataset folder, or what is left of one (its info.json may be the file that was lost)."""
    return any((root / rel).exists() for rel in (layout.INFO, layout.PILWORLD, META_MANIFEST, layout.EPISODES_DIR))


def _episode_files(store: EpisodeStore, row: dict[str, Any]) -> list[tuple[str, str]]:
    """(relative path, kind "data"|"video") of one episode's files, from its row and the path templates."""
    data = store.data_path.format(chunk_index=int(row["data/chunk_index"]), file_index=int(row["data/file_index"]))
    out = [(data, "data")]
    for key in store.video_keys:
        c, f = row.get(f"videos/{key}/chunk_index"), row.get(f"videos/{key}/file_index")
        if c is not None and f is not None:
            out.append((store.video_path.format(video_key=key, chunk_index=int(c), file_index=int(f)), "video"))
    return out


def _structure(path: Path, kind: str, rows: int | None) -> str | None:
    if kind == "video":
        return mp4_problem(path)
    return parquet_problem(path, rows)


def check_dataset(
    root: str | Path,
    *,
    hash_files: bool,
    label: str = ".",
    on_episode: Callable[[int, int], None] | None = None,
) -> DatasetCheck:
    """Check every file of every episode of the dataset at ``root`` against its manifest.

    ``on_episode(done, total)`` is called after each episode (a progress bar). Raises
    :class:`~pilworld.data.reader.DatasetError` only when ``root`` is not a dataset at all.
    """
    root = Path(root)
    if not is_dataset(root):
        raise DatasetError(f"{root}: not a dataset (no {layout.INFO})")
    check = DatasetCheck(root)

    def problem(path: str, kind: str, detail: str, episode: int | None = None) -> None:
        check.problems.append(Problem(label, path, kind, detail, episode))

    if not (root / layout.INFO).is_file():
        problem(layout.INFO, "missing", "missing")
        return check
    try:
        info = read_info(root)
    except DatasetError as err:
        problem(layout.INFO, "unreadable", str(err).split(": ", 1)[-1])
        return check

    # the dataset's own files first: if the episodes tables are gone, so are the episodes' manifests
    try:
        meta = read_meta_manifest(root)
    except ValueError as err:
        problem(META_MANIFEST, "unreadable", str(err).split(": ", 1)[-1])
        meta = None
    for rel, want in (meta or {}).items():
        check.files += 1
        bad = check_file(root, rel, want, hash_files=hash_files)
        if bad is not None:
            problem(rel, bad.kind, bad.detail)
    try:  # the outcomes table keeps its own manifest (judges rewrite it, not the episode writer)
        outcomes = read_meta_manifest(root, OUTCOMES_MANIFEST)
    except ValueError as err:
        problem(OUTCOMES_MANIFEST, "unreadable", str(err).split(": ", 1)[-1])
        outcomes = None
    for rel, want in (outcomes or {}).items():
        check.files += 1
        bad = check_file(root, rel, want, hash_files=hash_files)
        if bad is not None:
            problem(rel, bad.kind, bad.detail)
    for bad in backup_problems(root, hash_files=hash_files):  # the second copy a resume restores tables from
        check.files += 1
        problem(bad.path, bad.kind, bad.detail)
    try:
        store = EpisodeStore(root)
        rows = store.episodes
    except DatasetError as err:
        text = str(err)
        path, _, why = text.partition(": ")
        rel = Path(path).relative_to(root).as_posix() if path.startswith(str(root)) else path
        if not any(p.path == rel for p in check.problems):
            problem(rel, "unreadable", why or text)
        return check
    total = int(info.get("total_episodes", len(rows)) or 0)
    if total != len(rows) and not check.problems:
        problem(layout.EPISODES_DIR, "count", f"holds {len(rows)} episodes, {layout.INFO} says {total}")
    check.episodes = len(rows)
    for index, row in enumerate(rows):
        try:
            manifest = parse_manifest(row.get(MANIFEST_COLUMN), source=f"episode {index}")
        except ValueError as err:
            problem(layout.EPISODES_DIR, "unreadable", str(err), index)
            manifest = None
        files = _episode_files(store, row)
        if manifest is None:
            check.no_manifest += 1
        for rel, kind in files:
            check.files += 1
            entry: FileEntry | None = (manifest or {}).get(rel)
            if entry is not None:
                bad = check_file(root, rel, entry, hash_files=hash_files)
                if bad is not None:
                    problem(rel, bad.kind, bad.detail, index)
                    continue
            elif not (root / rel).is_file():
                problem(rel, "missing", "missing", index)
                continue
            if entry is None or hash_files:  # no manifest to trust, or a full check: the structure too
                broken = _structure(root / rel, kind, None)
                if broken is not None:
                    problem(rel, "truncated" if "truncated" in broken else "unreadable", broken, index)
        if on_episode is not None:
            on_episode(index + 1, len(rows))
    return check


@dataclass
class VerifyReport:
    """The result of ``pilworld data verify PATH``."""

    path: str
    hashed: bool
    datasets: list[str] = field(default_factory=list)
    episodes: int = 0
    files: int = 0
    no_manifest: int = 0
    problems: list[Problem] = field(default_factory=list)

    @property
    def ok(self) -> bool:
        return not self.problems

    def summary(self) -> str:
        state = "OK" if self.ok else f"DAMAGED: {len(self.problems)} problem(s)"
        damaged = len({(p.dataset, p.episode) for p in self.problems if p.episode is not None})
        note = f", {self.no_manifest} episode(s) with no manifest (checked for presence and structure only)"
        return (
            f"{self.path}: {state}; {len(self.datasets)} dataset(s), {self.episodes} episodes, {self.files} files"
            f" checked ({'sha256' if self.hashed else 'sizes only'}), {damaged} episode(s) damaged"
            + (note if self.no_manifest else "")
        )

    def to_json(self) -> dict[str, Any]:
        d = asdict(self)
        d["ok"] = self.ok
        return d


def _sidecar_problems(root: Path, datasets: dict[str, DatasetCheck]) -> list[Problem]:
    out: list[Problem] = []
    for rel in RUN_JSON:
        path = root / rel
        label, _, name = rel.rpartition("/")
        own = datasets.get(label or ".")
        if own is not None and any(p.path == name for p in own.problems):
            continue  # already named by the dataset's own check (pilworld.data.backup)
        if path.is_file():
            try:
                text = path.read_text(encoding="utf-8")
                for line in text.splitlines() if path.suffix == ".jsonl" else [text]:
                    json.loads(line)
            except (ValueError, UnicodeDecodeError) as err:
                out.append(Problem(".", rel, "unreadable", f"is not valid JSON ({err})"))
    for label, check in datasets.items():
        path = check.root / layout.OUTCOMES
        if not path.is_file() or any(p.path == layout.OUTCOMES for p in check.problems):
            continue
        why = parquet_problem(path)
        if why is not None:
            out.append(Problem(label, layout.OUTCOMES, "unreadable", why))
            continue
        from pilworld.data.outcomes import read_outcomes

        try:
            beyond = sorted({o.episode_index for o in read_outcomes(check.root) if o.episode_index >= check.episodes})
        except (ValueError, TypeError, KeyError) as err:
            out.append(Problem(label, layout.OUTCOMES, "unreadable", f"has invalid rows ({err})"))
            continue
        if beyond and not check.problems:
            out.append(
                Problem(label, layout.OUTCOMES, "count", f"judges episode(s) {beyond} the dataset does not hold")
            )
    return out


def find_datasets(path: Path) -> dict[str, Path]:
    """The datasets of ``path``: itself and/or its ``starts/`` folder. Raises DatasetError when there are none."""
    found = {label: p for label, p in ((".", path), (STARTS_DIR, path / STARTS_DIR)) if is_dataset(p)}
    if not found:
        if not path.exists():
            raise DatasetError(f"{path}: no such folder")
        raise DatasetError(f"{path}: not a dataset or run folder (no {layout.INFO}, nor {STARTS_DIR}/{layout.INFO})")
    return found


def verify(path: str | Path, *, hash_files: bool = True, progress: bool = False) -> VerifyReport:
    """Check every dataset in ``path`` (a dataset, or a paired / imagined-only run folder) and its sidecars."""
    from tqdm import tqdm

    root = Path(path)
    found = find_datasets(root)
    report = VerifyReport(path=str(root), hashed=hash_files, datasets=list(found))
    checks: dict[str, DatasetCheck] = {}
    for label, ds in found.items():
        bar = tqdm(desc=f"verify {label}", unit="episode", disable=not progress, leave=False)

        def tick(done: int, total: int, bar: Any = bar) -> None:
            bar.total = total
            bar.update(done - bar.n)

        check = check_dataset(ds, hash_files=hash_files, label=label, on_episode=tick)
        bar.close()
        checks[label] = check
        report.episodes += check.episodes
        report.files += check.files
        report.no_manifest += check.no_manifest
        report.problems += check.problems
    report.problems += _sidecar_problems(root, checks)
    return report
