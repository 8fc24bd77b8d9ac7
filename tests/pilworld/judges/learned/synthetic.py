"""A tiny labelled dataset a judge can learn (not a test module): success is a square ending in the goal corner.

Every episode shows a white square on a coloured background; over its frames the square moves from a
random start to its end position. Successful episodes end with the square in the top-left quadrant of
every view, failures elsewhere: visible in the frames, in nothing else (state and instruction are the
same for both classes).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from pilworld.data.episode import Episode
from pilworld.data.outcomes import Outcome, record_outcomes
from pilworld.data.spec import DatasetSpec
from pilworld.data.writer import EpisodeWriter

SIZE = 32
LENGTH = 6
VIEWS = ("cam_a", "cam_b")
INSTRUCTION = "put the square in the corner."


def make_episode(k: int, success: bool, views: tuple[str, ...] = VIEWS, size: int = SIZE) -> Episode:
    rng = np.random.default_rng(k)
    start = rng.integers(0, size - 8, 2)
    half = size // 2 - 8
    end = rng.integers(0, half, 2) if success else rng.integers(half + 8, size - 8, 2)
    images = {}
    for i, view in enumerate(views):
        frames = np.zeros((LENGTH, size, size, 3), dtype=np.uint8)
        frames[...] = rng.integers(30, 120, 3).astype(np.uint8)
        for f in range(LENGTH):
            y, x = (start + (end - start) * min(f / (LENGTH - 3), 1.0)).astype(int)
            frames[f, y : y + 8, x : x + 8] = 230 - 10 * i
        images[view] = frames
    state = rng.normal(0, 0.1, (LENGTH, 4)).astype(np.float32)
    return Episode(images=images, state=state, action=state.copy(), task=INSTRUCTION, seed=k, checkpoint="c")


def write_labelled(
    root: Path, episodes: int = 48, first: int = 0, judge_id: str = "sim_checker", views: tuple[str, ...] = VIEWS
) -> Path:
    names = ("a", "b", "c", "d")
    spec = DatasetSpec(
        fps=10, views={v: (SIZE, SIZE) for v in views}, video_mode="lossless", state_names=names, action_names=names
    )
    labels = [(first + k) % 2 == 0 for k in range(episodes)]
    with EpisodeWriter(root, spec, durable=False) as writer:
        for k, ok in enumerate(labels):
            writer.append(make_episode(first + k, ok, views))
    kind = "sim_state" if judge_id == "sim_checker" else "human"
    record_outcomes(root, [Outcome(k, judge_id, kind, ok, LENGTH) for k, ok in enumerate(labels)])
    return root
