"""Judges and their labels in SQLite: ``RUN_DIR/annotations.sqlite``.

Tables (schema version 1):

* ``meta(key, value)`` — ``secret``: 32 random bytes (hex) from which item ids, the judges' episode
  orders and cache file names are derived; ``schema``.
* ``judges(judge, token_sha256, created)`` — judge 1..N; only a SHA-256 of each token is kept, so a
  copied database does not let anyone log in, and tokens cannot be shown again after the first start.
* ``labels(judge, episode_index, success, first_hallucination_frame, category, updated_at)`` —
  one row per (judge, episode); revising replaces it.

The server is threaded: every operation opens its own connection (sqlite3 connections must not be
shared between threads) and writes in one short ``BEGIN IMMEDIATE`` transaction. WAL mode lets readers
run beside the one writer, ``busy_timeout`` makes a second writer wait instead of failing, and
``synchronous=FULL`` makes a committed label survive a killed process and a power cut alike.
"""

from __future__ import annotations

import datetime as dt
import hashlib
import hmac
import secrets
import sqlite3
from collections.abc import Iterator
from contextlib import closing, contextmanager
from dataclasses import dataclass
from pathlib import Path

DB_FILE = "annotations.sqlite"
SCHEMA_VERSION = "1"
BUSY_TIMEOUT_MS = 10_000  # a writer waits this long for another one (writes take ~ms)
TOKEN_BYTES = 24  # secrets.token_urlsafe(24): 32 characters, 192 bits

SCHEMA = """
CREATE TABLE IF NOT EXISTS meta (key TEXT PRIMARY KEY, value TEXT NOT NULL);
CREATE TABLE IF NOT EXISTS judges (
    judge INTEGER PRIMARY KEY,
    token_sha256 TEXT NOT NULL UNIQUE,
    created TEXT NOT NULL
);
CREATE TABLE IF NOT EXISTS labels (
    judge INTEGER NOT NULL REFERENCES judges(judge),
    episode_index INTEGER NOT NULL CHECK (episode_index >= 0),
    success INTEGER NOT NULL CHECK (success IN (0, 1)),
    first_hallucination_frame INTEGER CHECK (first_hallucination_frame IS NULL OR first_hallucination_frame >= 0),
    category TEXT,
    updated_at TEXT NOT NULL,
    PRIMARY KEY (judge, episode_index)
);
"""


class StoreError(ValueError):
    """The annotation database cannot be opened or does not fit the request; the message says why."""


@dataclass(frozen=True)
class Label:
    """One judge's label of one episode (``category`` is set iff a hallucination frame is)."""

    success: bool
    first_hallucination_frame: int | None
    category: str | None

    def to_json(self) -> dict[str, object]:
        return {
            "success": self.success,
            "first_hallucination_frame": self.first_hallucination_frame,
            "category": self.category,
        }


@dataclass(frozen=True)
class StoredLabel:
    judge: int
    episode_index: int
    label: Label
    updated_at: dt.datetime


def token_hash(token: str) -> str:
    return hashlib.sha256(token.encode("utf-8")).hexdigest()


def _now() -> str:
    return dt.datetime.now(dt.UTC).isoformat(timespec="microseconds")


class AnnotationStore:
    """The annotation database of one run folder (created on first use)."""

    def __init__(self, run_dir: str | Path) -> None:
        self.path = Path(run_dir) / DB_FILE
        with self._transaction() as db:
            # statement by statement: executescript() would commit the open transaction first
            for statement in SCHEMA.split(";"):
                if statement.strip():
                    db.execute(statement)
            row = db.execute("SELECT value FROM meta WHERE key = 'schema'").fetchone()
            if row is None:
                db.execute("INSERT INTO meta VALUES ('schema', ?)", (SCHEMA_VERSION,))
                db.execute("INSERT INTO meta VALUES ('secret', ?)", (secrets.token_hex(32),))
            elif row[0] != SCHEMA_VERSION:
                raise StoreError(f"{self.path}: schema version {row[0]!r}; this pilworld reads {SCHEMA_VERSION!r}")
        with closing(self._connect()) as db:
            self.secret = bytes.fromhex(db.execute("SELECT value FROM meta WHERE key = 'secret'").fetchone()[0])

    # ------------------------------------------------------------------ connections

    def _connect(self) -> sqlite3.Connection:
        try:
            # isolation_level=None: no implicit transactions; every write below says BEGIN IMMEDIATE itself.
            db = sqlite3.connect(self.path, timeout=BUSY_TIMEOUT_MS / 1000, isolation_level=None)
            db.execute(f"PRAGMA busy_timeout = {BUSY_TIMEOUT_MS}")
            db.execute("PRAGMA journal_mode = WAL")  # persistent in the file; cheap to repeat
            db.execute("PRAGMA synchronous = FULL")
            db.execute("PRAGMA foreign_keys = ON")
        except sqlite3.DatabaseError as err:
            raise StoreError(f"{self.path}: cannot open the annotation database: {err}") from None
        return db

    @contextmanager
    def _transaction(self) -> Iterator[sqlite3.Connection]:
        with closing(self._connect()) as db:
            db.execute("BEGIN IMMEDIATE")  # take the write lock now: no deadlock upgrading a read lock later
            try:
                yield db
            except BaseException:
                db.execute("ROLLBACK")
                raise
            db.execute("COMMIT")

    # ------------------------------------------------------------------ derived secrets

    def derive(self, purpose: str) -> str:
        """HMAC-SHA256 of ``purpose`` under the run's secret (hex): stable across restarts, unguessable."""
        return hmac.new(self.secret, purpose.encode("utf-8"), hashlib.sha256).hexdigest()

    # ------------------------------------------------------------------ judges

    def judges(self) -> list[int]:
        with closing(self._connect()) as db:
            return [int(r[0]) for r in db.execute("SELECT judge FROM judges ORDER BY judge")]

    def ensure_judges(self, count: int, *, new_tokens: bool = False) -> dict[int, str]:
        """Make judges 1..``count`` exist; returns the tokens issued now (judge → token).

        Judges created earlier keep their tokens (only hashes are stored, so they are not returned)
        unless ``new_tokens``, which issues every judge a fresh one and invalidates the old. Labels stay.
        """
        if isinstance(count, bool) or not isinstance(count, int) or count < 1:
            raise StoreError(f"judges: expected an integer >= 1, got {count!r}")
        issued: dict[int, str] = {}
        with self._transaction() as db:
            have = [int(r[0]) for r in db.execute("SELECT judge FROM judges ORDER BY judge")]
            if len(have) > count:
                raise StoreError(
                    f"judges: {self.path} already has {len(have)} judges; pass --judges {len(have)} or more "
                    "(judges are never removed: their labels would be orphaned)"
                )
            for judge in range(1, count + 1):
                if judge in have and not new_tokens:
                    continue
                token = secrets.token_urlsafe(TOKEN_BYTES)
                db.execute(
                    "INSERT INTO judges VALUES (?, ?, ?) "
                    "ON CONFLICT(judge) DO UPDATE SET token_sha256 = excluded.token_sha256",
                    (judge, token_hash(token), _now()),
                )
                issued[judge] = token
        return issued

    def judge_of(self, token: str) -> int | None:
        """The judge holding ``token``, or None."""
        digest = token_hash(token)
        with closing(self._connect()) as db:
            rows = db.execute("SELECT judge, token_sha256 FROM judges").fetchall()
        # compare_digest on every row: the lookup time does not depend on how much of a hash matched
        found = [int(j) for j, h in rows if hmac.compare_digest(str(h), digest)]
        return found[0] if found else None

    # ------------------------------------------------------------------ labels

    def put_label(self, judge: int, episode_index: int, label: Label) -> None:
        """Insert or replace one label; durable once this returns."""
        with self._transaction() as db:
            db.execute(
                "INSERT INTO labels VALUES (?, ?, ?, ?, ?, ?) ON CONFLICT(judge, episode_index) DO UPDATE SET "
                "success = excluded.success, first_hallucination_frame = excluded.first_hallucination_frame, "
                "category = excluded.category, updated_at = excluded.updated_at",
                (
                    judge,
                    episode_index,
                    int(label.success),
                    label.first_hallucination_frame,
                    label.category,
                    _now(),
                ),
            )

    def labels_of(self, judge: int) -> dict[int, Label]:
        """A judge's labels by episode index."""
        return {s.episode_index: s.label for s in self.all_labels(judge)}

    def label(self, judge: int, episode_index: int) -> Label | None:
        with closing(self._connect()) as db:
            row = db.execute(
                "SELECT success, first_hallucination_frame, category FROM labels WHERE judge = ? AND episode_index = ?",
                (judge, episode_index),
            ).fetchone()
        return None if row is None else Label(bool(row[0]), row[1], row[2])

    def all_labels(self, judge: int | None = None) -> list[StoredLabel]:
        """Every label (of one judge, if given), ordered by (judge, episode)."""
        where, args = ("WHERE judge = ?", (judge,)) if judge is not None else ("", ())
        with closing(self._connect()) as db:
            rows = db.execute(
                "SELECT judge, episode_index, success, first_hallucination_frame, category, updated_at "
                f"FROM labels {where} ORDER BY judge, episode_index",
                args,
            ).fetchall()
        return [
            StoredLabel(int(j), int(e), Label(bool(s), f, c), dt.datetime.fromisoformat(str(u)))
            for j, e, s, f, c, u in rows
        ]

    def counts(self) -> dict[int, int]:
        """Labels per judge (every judge listed, 0 included)."""
        with closing(self._connect()) as db:
            rows = db.execute(
                "SELECT j.judge, COUNT(l.episode_index) FROM judges j LEFT JOIN labels l ON l.judge = j.judge "
                "GROUP BY j.judge ORDER BY j.judge"
            ).fetchall()
        return {int(j): int(n) for j, n in rows}
