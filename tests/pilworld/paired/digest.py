"""A comparable summary of a paired-run dataset: everything stored except wall-clock times."""

from __future__ import annotations

import hashlib
from pathlib import Path
from typing import Any

from pilworld.data.outcomes import read_outcomes
from pilworld.data.reader import EpisodeStore


def _h(data: bytes) -> str:
    return hashlib.sha256(data).hexdigest()[:16]


def dataset_digest(root: str | Path) -> list[Any]:
    store = EpisodeStore(root)
    out: list[Any] = []
    for i in range(store.num_episodes):
        ep = store.load(i)
        out.append(
            (
                ep.origin,
                ep.subtask_index,
                ep.checkpoint,
                ep.seed,
                ep.task,
                sorted(ep.extra.items()),
                _h(ep.state.tobytes()),
                _h(ep.action.tobytes()),
                _h(ep.rounds().tobytes()),
                {v: _h(f.tobytes()) for v, f in sorted(ep.images.items())},
            )
        )
    verdicts = sorted((o.episode_index, o.judge_id, o.success, o.num_frames) for o in read_outcomes(root))
    return [out, verdicts]
