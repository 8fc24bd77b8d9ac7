"""The pairs of a paired run: which stored episodes are the two branches of one subtask, and their verdicts.

A paired run (``pilworld.paired.runner``, docs/paired.md) stores one episode per branch with
``extra.pair`` naming the pair (``task/checkpoint/seedS/subtaskK``), ``extra.task`` the task (older runs:
``extra.sim_task``) and ``checkpoint`` the policy. A pair is *complete* when both its imagined and its real episode
are stored; only complete pairs are scored (a run still in progress has an incomplete last pair).
Episodes without ``extra.pair`` (e.g. collected demonstrations in the same folder) are ignored and
counted.
"""

from __future__ import annotations

import json
from collections import defaultdict
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from pilworld.data.outcomes import Outcome, read_outcomes
from pilworld.data.reader import EpisodeStore


@dataclass(frozen=True)
class Pair:
    """One subtask run in both branches: the pair id, its setting and the two episode indices."""

    pair_id: str
    task: str  # the task's name (extra.task; older runs extra.sim_task), else the instruction
    checkpoint: str
    imagined: int  # episode index of the imagined branch
    real: int  # episode index of the real branch

    @property
    def setting(self) -> tuple[str, str]:
        return (self.task, self.checkpoint)


@dataclass
class PairedEpisodes:
    """The complete pairs of a dataset (in order of their imagined episode) and every verdict by episode."""

    root: Path
    pairs: list[Pair]
    verdicts: dict[int, list[Outcome]] = field(default_factory=dict)  # episode index → its verdicts
    incomplete: list[str] = field(default_factory=list)  # pair ids with one branch stored
    unpaired_episodes: int = 0  # episodes without extra.pair

    def outcomes(self, episode: int) -> list[Outcome]:
        return self.verdicts.get(episode, [])


def _extra(row: dict[str, Any]) -> dict[str, Any]:
    raw = row.get("extra")
    if not raw:
        return {}
    value = json.loads(raw) if isinstance(raw, str) else raw
    return value if isinstance(value, dict) else {}


def is_paired(store: EpisodeStore) -> bool:
    """Whether any episode of ``store`` belongs to a pair (a paired run; metrics and the report need pairs)."""
    try:
        return any("pair" in _extra(r) for r in store.episodes)
    except (TypeError, json.JSONDecodeError):
        return False


def _task(row: dict[str, Any], extra: dict[str, Any]) -> str:
    for key in ("task", "sim_task"):  # task files record ``task``; older runs ``sim_task`` only
        if extra.get(key):
            return str(extra[key])
    return next((str(t) for t in row.get("tasks") or [] if str(t).strip()), "")


def load_pairs(root: str | Path, store: EpisodeStore | None = None) -> PairedEpisodes:
    """Group the episodes of ``root`` into pairs by ``extra.pair``; raise ``ValueError`` on a malformed pair."""
    store = store or EpisodeStore(root)
    by_pair: dict[str, dict[str, int]] = defaultdict(dict)
    rows: dict[int, tuple[dict[str, Any], dict[str, Any]]] = {}
    unpaired = 0
    for row in store.episodes:
        index = int(row["episode_index"])
        extra = _extra(row)
        pair_id = extra.get("pair")
        if not pair_id:
            unpaired += 1
            continue
        origin = str(row.get("origin") or "")
        if origin not in ("real", "imagined"):
            raise ValueError(f"{store.root}: episode {index} of pair {pair_id!r} has origin {origin!r}")
        if origin in by_pair[str(pair_id)]:
            first = by_pair[str(pair_id)][origin]
            raise ValueError(f"{store.root}: pair {pair_id!r} has two {origin} episodes ({first} and {index})")
        by_pair[str(pair_id)][origin] = index
        rows[index] = (row, extra)
    pairs: list[Pair] = []
    incomplete: list[str] = []
    for pair_id, branches in by_pair.items():
        if set(branches) != {"real", "imagined"}:
            incomplete.append(pair_id)
            continue
        row, extra = rows[branches["imagined"]]
        pairs.append(
            Pair(
                pair_id=pair_id,
                task=_task(row, extra),
                checkpoint=str(row.get("checkpoint") or ""),
                imagined=branches["imagined"],
                real=branches["real"],
            )
        )
    pairs.sort(key=lambda p: p.imagined)
    verdicts: dict[int, list[Outcome]] = defaultdict(list)
    for o in read_outcomes(store.root):
        verdicts[o.episode_index].append(o)
    return PairedEpisodes(
        root=store.root, pairs=pairs, verdicts=dict(verdicts), incomplete=sorted(incomplete), unpaired_episodes=unpaired
    )
