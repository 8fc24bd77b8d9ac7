"""The ladder's settings: what one run measures (:class:`LadderConfig`) and the names every rung shares."""

from __future__ import annotations

import hashlib
import json
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from pilworld.paired.runner import PairedSubtask, plan_subtasks
from pilworld.types import LEFT_GRIP, RIGHT_GRIP, ChunkSpec
from simrig.files import SIM_RIG

DEFAULT_OUT = Path("bench_runs") / "wm_ladder"
LADDER_SEED0 = 8_000_000
TASKS = ("sort_cubes", "stack_bowls", "stack_blocks")
RUNGS = ("state_contract", "representation", "judge_fairness", "teacher_forced")
STATE_MODES = ("real", "commanded", "arms_commanded")
DEGRADATIONS = ("plain", "autoencoded", "blur", "artefact")
QUICK_CHECKPOINTS = ("scripted_step_01k", "scripted_step_05k", "scripted_step_30k")
SUBTASKS = {"quick": 1, "full": 2}  # per task × checkpoint, every rung
GRIPS = (LEFT_GRIP, RIGHT_GRIP)
HEAD = "cam_high"
VERSION = 1  # bump when a record's meaning changes: cached records of other versions are not reused

Frames = NDArray[np.uint8]


@dataclass(frozen=True)
class LadderConfig:
    """What one ladder run measures; every field has the bench's default."""

    model: str = ""  # a world-model folder; "" = pilworld.world_model.DEFAULT_CHECKPOINT
    rig: str = str(SIM_RIG)
    quick: bool = False
    subtasks: int | None = None  # per task × checkpoint; None = SUBTASKS[quick | full]
    tasks: tuple[str, ...] = TASKS
    checkpoints: tuple[str, ...] | None = None  # None: QUICK_CHECKPOINTS (quick) or every scripted one
    rungs: tuple[str, ...] = RUNGS
    spec: ChunkSpec = field(default_factory=ChunkSpec)
    seed0: int = LADDER_SEED0
    out: str = str(DEFAULT_OUT)
    judge: str = ""  # a learned judge folder beside the hand-written one; "" = the shipped one, "none" = none

    def __post_init__(self) -> None:
        s = self.subtasks
        if s is not None and (isinstance(s, bool) or not isinstance(s, int) or s < 1):
            raise ValueError(f"subtasks: expected an integer >= 1, got {s!r}")
        unknown = [r for r in self.rungs if r not in RUNGS]
        if unknown or not self.rungs:
            raise ValueError(f"rungs: unknown rung(s) {unknown or list(self.rungs)} (known: {', '.join(RUNGS)})")
        from simrig.tasks import TASK_NAMES

        bad = [t for t in self.tasks if t not in TASK_NAMES]
        if bad or not self.tasks:
            raise ValueError(f"tasks: unknown task(s) {bad or list(self.tasks)} (known: {', '.join(TASK_NAMES)})")
        if self.checkpoints is not None:
            from pilworld.policies.scripted import CHECKPOINTS

            names = [c.name for c in CHECKPOINTS]
            bad = [c for c in self.checkpoints if c not in names]
            if bad or not self.checkpoints:
                raise ValueError(f"checkpoints: unknown scripted checkpoint(s) {bad or []} (known: {', '.join(names)})")

    @property
    def judge_path(self) -> Path | None:
        """The learned judge that rungs 2 and 3 run beside the hand-written one (None: only the hand-written)."""
        if self.judge == "none":
            return None
        from pilworld.judges.learned.shipped import SHIPPED_JUDGE

        return Path(self.judge) if self.judge else SHIPPED_JUDGE

    @property
    def model_path(self) -> Path:
        from pilworld.world_model import V1_CHECKPOINT

        return Path(self.model) if self.model else Path(V1_CHECKPOINT)  # the ladder was first climbed with v1

    @property
    def subtasks_per_setting(self) -> int:
        return self.subtasks if self.subtasks is not None else SUBTASKS["quick" if self.quick else "full"]

    @property
    def checkpoint_names(self) -> tuple[str, ...]:
        if self.checkpoints is not None:
            return self.checkpoints
        if self.quick:
            return QUICK_CHECKPOINTS
        from pilworld.policies.scripted import CHECKPOINTS

        return tuple(c.name for c in CHECKPOINTS)

    def plan(self) -> list[PairedSubtask]:
        from simrig.tasks import make_task

        plan: list[PairedSubtask] = []
        for t in self.tasks:
            task = make_task(t)
            plan += plan_subtasks(
                t, self.subtasks_per_setting, self.seed0, self.checkpoint_names, task.num_subtasks, task.instruction
            )
        return plan


def check_model_folder(path: Path) -> None:
    """A one-line ``ValueError`` unless ``path`` is a world-model folder load_world_model can read."""
    from pilworld.world_model.folder import CONFIG_FILE

    if not path.is_dir():
        raise ValueError(f"model: {path} is not a folder (expected a world-model folder with {CONFIG_FILE})")
    if not (path / CONFIG_FILE).is_file():
        raise ValueError(f"model: {path} is not a world-model folder ({CONFIG_FILE} missing)")


def digest(obj: Any) -> str:
    return hashlib.sha256(json.dumps(obj, sort_keys=True, default=str).encode()).hexdigest()[:16]


def safe_pair_id(pair_id: str) -> str:
    return pair_id.replace("/", "__")
