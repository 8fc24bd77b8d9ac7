"""Tiny paired datasets written straight to the episode store, for metric tests that need no simulator."""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from pilworld.data.episode import Episode
from pilworld.data.spec import DatasetSpec
from pilworld.data.writer import EpisodeWriter

SIZE = 16  # pixels; SSIM needs at least 11
VIEWS = ("cam_high", "cam_left_wrist")
K = 3  # frames per round
ROUNDS = 2


@dataclass
class SynthPair:
    """One pair; the imagined branch is the real one plus ``offset`` grey levels in round 0."""

    task: str = "sort_cubes"
    checkpoint: str = "ckpt_a"
    subtask: int = 0
    offset: int = 0  # added to every imagined pixel of frames 1..K
    action_shift: dict[int, float] = field(default_factory=dict)  # imagined action row → added value
    branches: tuple[str, ...] = ("imagined", "real")

    @property
    def pair_id(self) -> str:
        return f"{self.task}/{self.checkpoint}/seed0/subtask{self.subtask}"


def spec() -> DatasetSpec:
    return DatasetSpec(fps=10, views={v: (SIZE, SIZE) for v in VIEWS}, video_mode="lossless")


def _episode(p: SynthPair, origin: str, rng_seed: int) -> Episode:
    rng = np.random.default_rng(rng_seed)
    T = 1 + ROUNDS * K
    real = {v: rng.integers(40, 200, size=(T, SIZE, SIZE, 3), dtype=np.uint8) for v in VIEWS}
    action = np.tile(np.linspace(0, 1, 14, dtype=np.float32), (T, 1)) + np.arange(T, dtype=np.float32)[:, None]
    images = real
    if origin == "imagined":
        images = {v: x.copy() for v, x in real.items()}
        for x in images.values():
            x[1 : K + 1] = (x[1 : K + 1].astype(np.int16) + p.offset).clip(0, 255).astype(np.uint8)
            x[K + 1 :] = 255 - x[K + 1 :]  # later rounds diverge completely: must not enter single-step
        action = action.copy()
        action[K + 1 :] += 0.5  # round 1 follows other observations: other actions
        for row, shift in p.action_shift.items():
            action[row] += shift
    rounds = np.concatenate([[0], np.repeat(np.arange(ROUNDS), K)]).astype(np.int64)
    return Episode(
        images=images,
        state=action.copy(),
        action=action,
        task="sort the cubes",
        origin=origin,
        subtask_index=p.subtask,
        checkpoint=p.checkpoint,
        seed=p.subtask,
        round_index=rounds,
        extra={"pair": p.pair_id, "sim_task": p.task},
    )


def write_paired(root: Path, pairs: list[SynthPair], *, unpaired: int = 0) -> Path:
    """Episodes imagined, real, imagined, real, … (both branches of a pair share their frames' seed)."""
    with EpisodeWriter(root, spec()) as writer:
        for i, p in enumerate(pairs):
            for origin in p.branches:
                writer.append(_episode(p, origin, rng_seed=i))
        for j in range(unpaired):
            ep = _episode(SynthPair(), "real", rng_seed=100 + j)
            writer.append(
                Episode(**{**{f: getattr(ep, f) for f in ep.__dataclass_fields__}, "extra": {"run": "collected"}})
            )
    return root
