"""The label store: concurrent writers, durability across connections, judges and tokens on reopening."""

from __future__ import annotations

import sqlite3
import threading
from pathlib import Path

import pytest

from pilworld.annotate.store import DB_FILE, AnnotationStore, Label, StoreError, token_hash

THREADS = 8
WRITES = 15


def test_concurrent_writers_lose_nothing(tmp_path: Path) -> None:
    store = AnnotationStore(tmp_path)
    store.ensure_judges(THREADS)
    errors: list[BaseException] = []
    start = threading.Barrier(THREADS)

    def write(judge: int) -> None:
        try:
            start.wait()
            for e in range(WRITES):
                # a revision of every label too: the second write must replace the first
                store.put_label(judge, e, Label(False, None, None))
                store.put_label(judge, e, Label(e % 2 == 0, e % 5 or None, "object appearing" if e % 5 else None))
        except BaseException as err:  # reported below: a thread's exception would otherwise vanish
            errors.append(err)

    threads = [threading.Thread(target=write, args=(j,)) for j in range(1, THREADS + 1)]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    assert not errors
    fresh = AnnotationStore(tmp_path)  # a new connection sees every committed row
    assert fresh.counts() == {j: WRITES for j in range(1, THREADS + 1)}
    for j in range(1, THREADS + 1):
        labels = fresh.labels_of(j)
        assert [labels[e].success for e in range(WRITES)] == [e % 2 == 0 for e in range(WRITES)]
        assert labels[5] == Label(False, None, None) and labels[6] == Label(True, 1, "object appearing")


def test_wal_mode_and_durable_settings(tmp_path: Path) -> None:
    store = AnnotationStore(tmp_path)
    db = sqlite3.connect(store.path)
    try:
        assert db.execute("PRAGMA journal_mode").fetchone()[0] == "wal"
    finally:
        db.close()


def test_tokens_are_stored_only_as_hashes(tmp_path: Path) -> None:
    store = AnnotationStore(tmp_path)
    tokens = store.ensure_judges(3)
    assert sorted(tokens) == [1, 2, 3] and len(set(tokens.values())) == 3
    assert all(len(t) == 32 for t in tokens.values())  # token_urlsafe(24)
    raw = b"".join(p.read_bytes() for p in tmp_path.iterdir() if p.name.startswith(DB_FILE))
    for judge, token in tokens.items():
        assert token.encode() not in raw
        assert store.judge_of(token) == judge
    assert store.judge_of("not-a-token") is None
    assert store.judge_of(token_hash(tokens[1])) is None  # the stored hash itself is no token


def test_reopening_resumes_judges_tokens_and_labels(tmp_path: Path) -> None:
    store = AnnotationStore(tmp_path)
    tokens = store.ensure_judges(2)
    store.put_label(1, 3, Label(True, None, None))
    again = AnnotationStore(tmp_path)
    assert again.secret == store.secret
    assert again.ensure_judges(2) == {}  # nothing new issued
    assert again.judge_of(tokens[2]) == 2
    more = again.ensure_judges(3)
    assert list(more) == [3]
    assert again.labels_of(1) == {3: Label(True, None, None)}


def test_new_tokens_invalidate_old_ones_and_keep_labels(tmp_path: Path) -> None:
    store = AnnotationStore(tmp_path)
    old = store.ensure_judges(2)
    store.put_label(2, 0, Label(False, 4, "cross-view conflict"))
    new = store.ensure_judges(2, new_tokens=True)
    assert sorted(new) == [1, 2] and set(new.values()).isdisjoint(old.values())
    assert store.judge_of(old[1]) is None and store.judge_of(new[1]) == 1
    assert store.labels_of(2) == {0: Label(False, 4, "cross-view conflict")}


def test_judges_are_never_removed(tmp_path: Path) -> None:
    store = AnnotationStore(tmp_path)
    store.ensure_judges(3)
    with pytest.raises(StoreError, match="already has 3 judges"):
        store.ensure_judges(2)
    with pytest.raises(StoreError, match="judges: expected an integer >= 1"):
        store.ensure_judges(0)
