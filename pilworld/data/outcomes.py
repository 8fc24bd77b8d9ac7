"""The outcomes sidecar ``meta/outcomes.parquet``: one row per (episode, judge).

Every judge — the simulator's privileged checker (``sim_state``), an image-only judge (``vision``) or
a person (``human``) — writes its verdict here; the metrics (success rates, |ΔSR|, HFR) are computed
from this table. Columns:

==============================  =========  ==========================================================
column                          type       meaning
==============================  =========  ==========================================================
episode_index                   int64      the episode judged
judge_id                        string     who judged (e.g. ``sim_state``, ``vlm-7b``, ``alice``)
judge_kind                      string     ``sim_state`` | ``vision`` | ``human``
success                         bool       did the episode achieve its subtask
first_hallucination_frame       int64      first frame showing a hallucination; null if none seen
num_frames                      int64      frames the judge saw (T in HFR = t_h / T)
judged_at                       timestamp  when the verdict was recorded (UTC)
judge_seconds                   float64    how long judging took (null when unknown)
==============================  =========  ==========================================================

A new verdict for an existing (episode, judge) pair replaces the old one. The file is rewritten
atomically under its own lock, so judges can record while a writer appends episodes.
"""

from __future__ import annotations

import datetime as dt
import fcntl
from collections.abc import Iterable, Iterator
from contextlib import contextmanager
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Literal

import pyarrow as pa
import pyarrow.parquet as pq

from pilworld.data import layout
from pilworld.data.backup import OUTCOMES_MANIFEST, back_up
from pilworld.io.atomic import write_json, write_parquet

JudgeKind = Literal["sim_state", "vision", "human"]
JUDGE_KINDS: tuple[str, ...] = ("sim_state", "vision", "human")

SCHEMA = pa.schema(
    [
        ("episode_index", pa.int64()),
        ("judge_id", pa.string()),
        ("judge_kind", pa.string()),
        ("success", pa.bool_()),
        ("first_hallucination_frame", pa.int64()),
        ("num_frames", pa.int64()),
        ("judged_at", pa.timestamp("us", tz="UTC")),
        ("judge_seconds", pa.float64()),
    ]
)


def _now() -> dt.datetime:
    return dt.datetime.now(dt.UTC)


@dataclass(frozen=True)
class Outcome:
    """One judge's verdict on one episode."""

    episode_index: int
    judge_id: str
    judge_kind: str
    success: bool
    num_frames: int
    first_hallucination_frame: int | None = None  # None: no hallucination seen (t_h = T)
    judged_at: dt.datetime = field(default_factory=_now)
    judge_seconds: float | None = None

    def __post_init__(self) -> None:
        if isinstance(self.episode_index, bool) or not isinstance(self.episode_index, int) or self.episode_index < 0:
            raise ValueError(f"episode_index: expected an integer >= 0, got {self.episode_index!r}")
        if not isinstance(self.judge_id, str) or not self.judge_id.strip():
            raise ValueError(f"judge_id: expected a non-empty string, got {self.judge_id!r}")
        if self.judge_kind not in JUDGE_KINDS:
            raise ValueError(f"judge_kind: expected one of {list(JUDGE_KINDS)}, got {self.judge_kind!r}")
        if not isinstance(self.success, bool):
            raise ValueError(f"success: expected True or False, got {self.success!r}")
        if isinstance(self.num_frames, bool) or not isinstance(self.num_frames, int) or self.num_frames < 1:
            raise ValueError(f"num_frames: expected an integer >= 1, got {self.num_frames!r}")
        t_h = self.first_hallucination_frame
        if t_h is not None and (isinstance(t_h, bool) or not isinstance(t_h, int) or not 0 <= t_h < self.num_frames):
            raise ValueError(
                f"first_hallucination_frame: expected None or an integer in [0, {self.num_frames}), got {t_h!r}"
            )
        if self.judged_at.tzinfo is None:
            raise ValueError(f"judged_at: expected a timezone-aware datetime, got {self.judged_at!r}")
        if self.judge_seconds is not None and not self.judge_seconds >= 0:
            raise ValueError(f"judge_seconds: expected None or seconds >= 0, got {self.judge_seconds!r}")

    @property
    def hallucination_free_fraction(self) -> float:
        """t_h / T of the paper's HFR (1.0 when no hallucination was seen)."""
        t_h = self.num_frames if self.first_hallucination_frame is None else self.first_hallucination_frame
        return t_h / self.num_frames

    def to_row(self) -> dict[str, Any]:
        return {
            "episode_index": self.episode_index,
            "judge_id": self.judge_id,
            "judge_kind": self.judge_kind,
            "success": self.success,
            "first_hallucination_frame": self.first_hallucination_frame,
            "num_frames": self.num_frames,
            "judged_at": self.judged_at,
            "judge_seconds": self.judge_seconds,
        }


def _write(root: Path, table: pa.Table) -> None:
    """Rewrite the table, then its manifest (under the lock). A writer killed between the two leaves a
    manifest one version behind, which verify reports; the next recorded verdict rewrites both."""
    from pilworld.data.manifest import meta_manifest_text

    write_parquet(root / layout.OUTCOMES, table)
    write_json(root / OUTCOMES_MANIFEST, meta_manifest_text(root, [root / layout.OUTCOMES]))
    back_up(root, [layout.OUTCOMES, OUTCOMES_MANIFEST])  # the manifest last: the backup is one whole generation


def read_outcomes(root: str | Path) -> list[Outcome]:
    """All verdicts of a dataset, ordered by (episode, judge); empty if none were recorded."""
    path = Path(root) / layout.OUTCOMES
    if not path.is_file():
        return []
    from pilworld.data.reader import DamagedDatasetError

    try:
        rows = pq.read_table(path).to_pylist()
        return [Outcome(**row) for row in sorted(rows, key=lambda r: (r["episode_index"], r["judge_id"]))]
    except (OSError, pa.ArrowException, TypeError, KeyError, ValueError) as err:  # cut short or overwritten
        detail = " ".join(str(err).split()[:12])
        raise DamagedDatasetError(f"{path}: outcomes table unreadable ({detail})") from None


def judges_with_verdicts(root: str | Path) -> list[str]:
    """The ids of every judge with a verdict in the dataset at ``root``, sorted."""
    return sorted({o.judge_id for o in read_outcomes(root)})


@contextmanager
def _locked(root: Path) -> Iterator[None]:
    (root / "meta").mkdir(parents=True, exist_ok=True)
    with (root / "meta" / ".outcomes.lock").open("a") as fh:
        fcntl.flock(fh, fcntl.LOCK_EX)  # blocking: judges wait for each other briefly
        try:
            yield
        finally:
            fcntl.flock(fh, fcntl.LOCK_UN)


def record_outcomes(root: str | Path, outcomes: Iterable[Outcome], *, num_episodes: int | None = None) -> int:
    """Add or replace verdicts; returns the number of rows in the table afterwards.

    With ``num_episodes`` (the dataset's episode count), verdicts on episodes that do not exist are
    rejected before anything is written.
    """
    root = Path(root)
    new = list(outcomes)
    if num_episodes is not None:
        bad = sorted({o.episode_index for o in new if o.episode_index >= num_episodes})
        if bad:
            raise ValueError(f"episode_index: {bad} not in {root} (it has {num_episodes} episodes)")
    with _locked(root):
        table = {(o.episode_index, o.judge_id): o for o in read_outcomes(root)}
        table.update({(o.episode_index, o.judge_id): o for o in new})
        rows = [table[k].to_row() for k in sorted(table)]
        _write(root, pa.Table.from_pylist(rows, schema=SCHEMA))
    return len(rows)


def replace_judge_outcomes(root: str | Path, judges: set[str], outcomes: Iterable[Outcome]) -> int:
    """Drop every row of ``judges`` and add ``outcomes`` in one locked rewrite; returns the rows dropped.

    :func:`record_outcomes` only adds or replaces (episode, judge) rows; a judge whose verdicts were
    withdrawn (a person who cleared a label) needs its rows replaced as a whole.
    """
    root = Path(root)
    new_rows = list(outcomes)
    with _locked(root):
        old = read_outcomes(root)
        keep = [o for o in old if o.judge_id not in judges]
        rows = {(o.episode_index, o.judge_id): o for o in [*keep, *new_rows]}
        table = pa.Table.from_pylist([rows[k].to_row() for k in sorted(rows)], schema=SCHEMA)
        _write(root, table)
    new = {(o.episode_index, o.judge_id) for o in new_rows}
    return sum(1 for o in old if o.judge_id in judges and (o.episode_index, o.judge_id) not in new)


def drop_episode_outcomes(root: str | Path, episodes: set[int]) -> int:
    """Drop every verdict on ``episodes`` (episodes being rewritten); returns the rows dropped."""
    root = Path(root)
    if not (root / layout.OUTCOMES).is_file():
        return 0
    with _locked(root):
        old = read_outcomes(root)
        keep = [o.to_row() for o in old if o.episode_index not in episodes]
        if len(keep) != len(old):
            _write(root, pa.Table.from_pylist(keep, schema=SCHEMA))
    return len(old) - len(keep)


def summarize(outcomes: list[Outcome]) -> dict[str, Any]:
    """Per judge: verdicts, success rate and mean t_h / T (the judge's HFR over its episodes)."""
    by_judge: dict[str, list[Outcome]] = {}
    for o in outcomes:
        by_judge.setdefault(o.judge_id, []).append(o)
    return {
        judge: {
            "kind": items[0].judge_kind,
            "episodes": len(items),
            "success_rate": sum(o.success for o in items) / len(items),
            "hallucination_free_ratio": sum(o.hallucination_free_fraction for o in items) / len(items),
        }
        for judge, items in sorted(by_judge.items())
    }
