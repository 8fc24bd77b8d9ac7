"""Which stored episodes carry a success label, and from whom (``pilworld judge train --labels``).

Labels are what a user already has (docs/judges.md, "Labels"): the simulator's checker on every
simulated real-branch episode (``sim_checker``), an operator's yes/no on hardware (``operator``), or the
annotation app's human judges (``human``: judges ``human_1 … human_N``, majority vote, ties left out).
Every verdict comes from the dataset's outcomes table; nothing else about the task is read.
"""

from __future__ import annotations

import re
from collections import Counter, defaultdict
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

from pilworld.data.outcomes import Outcome, read_outcomes
from pilworld.data.reader import DatasetError, EpisodeStore

LABEL_SOURCES = ("sim_checker", "operator", "human")
_HUMAN = re.compile(r"human_\d+")


class JudgeDataError(ValueError):
    """Training data a judge cannot learn from: no labels, one class only, datasets from different cameras."""


@dataclass(frozen=True)
class Labelled:
    root: Path
    index: int
    success: bool
    seed: int  # the layout seed: episodes of one layout stay in one fold (no leak between folds)


def _is_source(o: Outcome, source: str) -> bool:
    if source == "sim_checker":
        return o.judge_kind == "sim_state"
    if source == "operator":
        return o.judge_id == "operator"
    return bool(_HUMAN.fullmatch(o.judge_id))


def labels_of(outcomes: Sequence[Outcome], source: str) -> dict[int, bool]:
    """Episode → label from ``source``; human judges by majority, a tie gives no label."""
    if source not in LABEL_SOURCES:
        raise ValueError(f"--labels: expected one of {', '.join(LABEL_SOURCES)}, got {source!r}")
    votes: dict[int, list[bool]] = defaultdict(list)
    for o in outcomes:
        if _is_source(o, source):
            votes[o.episode_index].append(bool(o.success))
    out: dict[int, bool] = {}
    for ep, v in votes.items():
        yes = sum(v)
        if 2 * yes != len(v):
            out[ep] = 2 * yes > len(v)
    return out


def open_store(root: Path) -> EpisodeStore:
    if not root.is_dir():
        raise DatasetError(f"--data: {root} is not a folder")
    store = EpisodeStore(root)
    if store.num_episodes == 0:
        raise JudgeDataError(f"--data: {root} holds no episodes")
    return store


def labelled_episodes(roots: Sequence[Path], source: str) -> list[Labelled]:
    """Every episode of ``roots`` with a ``source`` label; :class:`JudgeDataError` when there is nothing to learn."""
    out: list[Labelled] = []
    for root in roots:
        store = open_store(root)
        outcomes = read_outcomes(root)
        labels = labels_of(outcomes, source)
        if not labels:
            have = Counter(o.judge_id for o in outcomes)
            said = ", ".join(f"{j} ×{n}" for j, n in sorted(have.items())) or "no verdicts at all"
            raise JudgeDataError(f"--data: {root} has no '{source}' labels (its outcomes table has {said})")
        seeds = {i: int(ep.get("seed", 0) or 0) for i, ep in enumerate(store.episodes)}
        out.extend(Labelled(root, i, ok, seeds.get(i, i)) for i, ok in sorted(labels.items()))
    counts = Counter(lab.success for lab in out)
    if len(counts) < 2:
        only = "succeeded" if True in counts else "failed"
        raise JudgeDataError(
            f"--data: all {len(out)} labelled episodes {only}; a judge needs successes and failures to learn from"
        )
    return out
