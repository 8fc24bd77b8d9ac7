"""A tiny simulated-rig-like dataset for the world-model training tests (not a test module).

Six episodes of 40 frames, 3 views at 32×32 with coloured squares that move with the joints, 14-d joint
states near the simulated rig's home pose, stored as the collector stores them (every Δ = 3rd control
step, ``steps_per_frame=3``, so clips use stride 1), with ``extra.sim_task`` naming two tasks and the
privileged checker's verdicts in ``meta/outcomes.parquet``.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from pilworld.collection.collect import JUDGE_ID
from pilworld.data.episode import Episode
from pilworld.data.outcomes import Outcome, record_outcomes
from pilworld.data.spec import DatasetSpec
from pilworld.data.writer import EpisodeWriter
from pilworld.types import DEFAULT_VIEWS
from simrig.poses import HOME_Q14

ROOT = Path(__file__).resolve().parents[4]
SIM_RIG = ROOT / "configs" / "rig" / "sim_dual_ur5e.yaml"
SIZE = 32
LENGTH = 40
EPISODES = 6
TASKS = ("taskA", "taskB")
INSTRUCTIONS = {"taskA": "stack the red block on the green one.", "taskB": "sort the blue cubes."}


def task_of(episode: int) -> str:
    return TASKS[episode % 2]


def success_of(episode: int) -> bool:
    """Episodes 0–2 succeed, 3–5 fail: each task has a success and a failure among its training episodes
    (with ``val_every_episode=3`` episodes 2 and 5 are validation)."""
    return episode < 3


def make_episode(k: int, length: int = LENGTH) -> Episode:
    rng = np.random.default_rng(k)
    t = np.arange(length, dtype=np.float64)[:, None]
    phase = rng.uniform(0, 2 * np.pi, size=(1, 14))
    state = HOME_Q14[None] + 0.15 * np.sin(0.12 * t + phase)
    state[:, [6, 13]] = 0.5 + 0.5 * np.cos(0.1 * t + phase[:, [6, 13]])  # grippers in [0, 1]
    action = np.concatenate([state[1:], state[-1:]])  # the command sent at frame i is the next state
    images = {}
    for i, view in enumerate(DEFAULT_VIEWS):
        frames = np.zeros((length, SIZE, SIZE, 3), dtype=np.uint8)
        frames[..., :] = np.array([40 + 20 * i, 60, 80 + 30 * (k % 3)], dtype=np.uint8)  # background
        for f in range(length):
            # A square per arm: its position follows two joints, so frames move smoothly with the state.
            for arm, colour in ((0, (230, 40, 40)), (7, (40, 220, 60))):
                x = round(12 + 40 * (state[f, arm] - HOME_Q14[arm])) + 4 * i
                y = round(12 + 40 * (state[f, arm + 1] - HOME_Q14[arm + 1]))
                x, y = np.clip(x, 0, SIZE - 8), np.clip(y, 0, SIZE - 8)
                frames[f, y : y + 8, x : x + 8] = colour
        images[view] = frames
    task = task_of(k)
    return Episode(
        images=images,
        state=state.astype(np.float32),
        action=action.astype(np.float32),
        task=INSTRUCTIONS[task],
        origin="real",
        checkpoint=f"ckpt-{k % 2}",
        seed=k,
        extra={"run": f"{task}/ckpt-{k % 2}/{k}", "sim_task": task, "parts": 1, "checker": "synthetic"},
    )


def write_dataset(root: Path, episodes: int = EPISODES) -> Path:
    """Write the dataset to ``root`` (lossless video, as the collector's ``dataset_spec`` at stride 3)."""
    spec = DatasetSpec(fps=10, views={v: (SIZE, SIZE) for v in DEFAULT_VIEWS}, video_mode="lossless", steps_per_frame=3)
    with EpisodeWriter(root, spec, durable=False) as writer:
        for k in range(episodes):
            writer.append(make_episode(k))
    record_outcomes(root, [Outcome(k, JUDGE_ID, "sim_state", success_of(k), LENGTH) for k in range(episodes)])
    return root
