"""A branch's :class:`~pilworld.rollout.Rollout` as a stored :class:`~pilworld.data.episode.Episode`.

Same clip structure as the collected data (``pilworld.collection.rollout``): frame 0 is the shared start,
frame ``i > 0`` the i-th observation at stride Δ, and the action stored with frame ``i`` is the
stride-aligned command whose effect frame ``i + 1`` shows (the last frame repeats the last command).
So a paired run can be read by the same clip indexer, judges and metrics as any other dataset.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from pilworld.data.episode import Episode
from pilworld.rollout import Rollout


def rollout_episode(rollout: Rollout, *, checkpoint: str, seed: int, extra: dict[str, Any]) -> Episode:
    observations = rollout.observations
    views = rollout.start.observation.views
    images = {v: np.stack([np.asarray(o.images[v]) for o in observations]) for v in views}
    state = np.stack([np.asarray(o.state, dtype=np.float32) for o in observations])
    actions = [seg.actions[seg.stride - 1 :: seg.stride] for seg in rollout.segments]
    action = np.concatenate([*actions, actions[-1][-1:]]).astype(np.float32)
    rounds = np.concatenate(
        [[0], *[np.full(len(seg.observations), r, dtype=np.int64) for r, seg in enumerate(rollout.segments)]]
    ).astype(np.int64)
    subtask = rollout.start.subtask
    return Episode(
        images=images,
        state=state,
        action=action,
        task=rollout.instruction,
        origin=rollout.origin,
        subtask_index=subtask.index,
        checkpoint=checkpoint,
        seed=seed,
        round_index=rounds,
        extra=extra,
    )
