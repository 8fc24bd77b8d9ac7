"""Clean real-branch episodes for the hallucination detector and fault tests, collected once per session.

``collect`` is resumable, so the second test module asking for the same folder gets the stored episodes
back in a fraction of a second instead of simulating them again.
"""

from __future__ import annotations

from pathlib import Path

from pilworld.collection.collect import collect
from pilworld.config.rig import RigConfig
from pilworld.data.episode import Episode
from pilworld.data.reader import EpisodeStore
from pilworld.policies.scripted import BEST_CHECKPOINT

ROOT = Path(__file__).resolve().parents[3]
SIM = ROOT / "configs" / "rig" / "sim_dual_ur5e.yaml"
TASK = "stack_blocks"  # 2 subtasks: the cheapest task to run whole (~15 s); three objects, arms that move
SEED = 4_100_000  # away from the training seeds (0-19) and the acceptance seeds (4,000,000+)


def clean_dataset(base: Path, *, appearance: str = "flat", seed: int = SEED) -> Path:
    """One run of the best checkpoint on stack_blocks: two subtask episodes of 76 frames."""
    root = base / (
        "hallucination_clean" if (appearance, seed) == ("flat", SEED) else f"hallucination_{appearance}_{seed}"
    )
    collect(
        root,
        rig_path=str(SIM),
        tasks=[TASK],
        checkpoints=[BEST_CHECKPOINT],
        episodes=1,
        seed0=seed,
        workers=1,
        progress=False,
        appearance=appearance,
    )
    return root


def clean_episodes(base: Path, *, appearance: str = "flat", seed: int = SEED) -> list[Episode]:
    store = EpisodeStore(clean_dataset(base, appearance=appearance, seed=seed))
    return [store.load(i) for i in range(store.num_episodes)]


def sim_rig() -> RigConfig:
    return RigConfig.load(SIM)
