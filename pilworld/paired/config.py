"""The settings of a paired run (``paired_config.json``) and how a stored run's settings compare on resume.

The real-branch source (:mod:`pilworld.paired.real_source`) and the runner both read them, so they live
apart from the runner.
"""

from __future__ import annotations

from collections.abc import Iterable, Sequence
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

from pilworld.io.run_folder import read_json_object
from pilworld.types import ChunkSpec
from simrig.tasks import Task

CONFIG_FILE = "paired_config.json"
TIMINGS_FILE = "paired_timings.jsonl"


def check_checkpoints(checkpoints: Sequence[str]) -> None:
    """One or more checkpoint names, none blank, none twice (paired and imagined-only runs alike)."""
    if not checkpoints or any(not c.strip() for c in checkpoints):
        raise ValueError(f"checkpoints: expected one or more names, got {checkpoints!r}")
    if len(set(checkpoints)) != len(checkpoints):
        raise ValueError(f"checkpoints: listed twice: {checkpoints!r}")


@dataclass
class PairedConfig:
    """Everything that decides a paired run's results (stored in ``paired_config.json``)."""

    rig: str
    # One task, several comma-separated ("sort_cubes,stack_bowls") or "all" (the paper's three); each a
    # packaged task's name or a task file's path (pilworld.collection.tasks).
    task: str
    checkpoints: list[str]
    subtasks: int
    out: str
    seed: int = 0
    world_model: str = ""  # a model folder; "" = the packaged checkpoint
    adapter: str = "auto"  # "auto": the task's LoRA adapter when the model has one; "none"; or a name
    steps: int | None = None  # sampling steps; None = the model's default
    video_mode: str = "lossless"  # bit-exact frames, so the two stored start frames compare byte for byte
    spec: ChunkSpec = field(default_factory=ChunkSpec)
    # A paired run with the same rig, seed and spec whose real branches are copied instead of re-run
    # (pilworld.paired.real_source); "" = run them. Not compared on resume: a copy equals a re-run.
    real_from: str = ""
    history: bool = True  # False: the no-history ablation at inference (the model's latent memory hidden)
    resize: bool = False  # True: a model of another image size runs through ResizedWorldModel
    instruction: str = ""  # the instruction given to the policy and recorded; "" = each task file's own
    appearance: str = "flat"  # the simulated scene's look (SimRobot appearance); a hardware rig is what it is

    def __post_init__(self) -> None:
        from pilworld.collection.tasks import APPEARANCES, check_instruction

        if isinstance(self.subtasks, bool) or not isinstance(self.subtasks, int) or self.subtasks < 1:
            raise ValueError(f"subtasks: expected an integer >= 1, got {self.subtasks!r}")
        check_checkpoints(self.checkpoints)
        if self.steps is not None and self.steps < 1:
            raise ValueError(f"steps: expected an integer >= 1, got {self.steps!r}")
        check_instruction(self.instruction, "instruction")
        if self.appearance not in APPEARANCES:
            raise ValueError(f"appearance: expected one of {', '.join(APPEARANCES)}, got {self.appearance!r}")

    @property
    def task_files(self) -> list[Task]:
        """The run's tasks, loaded and validated (a one-line ``ValueError`` naming the file otherwise)."""
        from pilworld.collection.tasks import resolve_tasks

        return resolve_tasks(self.task, what="task")

    @property
    def tasks(self) -> list[str]:
        """The names of the run's tasks (they key its pairs)."""
        return [t.name for t in self.task_files]

    def instruction_for(self, task: Task) -> str:
        """The instruction the policy gets (and the episodes record) for ``task``."""
        return self.instruction or task.instruction

    def to_json(self) -> dict[str, Any]:
        d = asdict(self)
        d.pop("out")
        return d


# Settings that may differ on resume: more subtasks extend a run; a copied real branch equals a re-run one.
UNCOMPARED = ("subtasks", "real_from")
TASK_HASHES = "task_sha256"  # paired_config.json: task name → Task.digest of the file the run used


def _config_defaults() -> dict[str, Any]:
    from dataclasses import MISSING, fields

    return {f.name: f.default for f in fields(PairedConfig) if f.default is not MISSING}


def same_rig(a: Any, b: Any) -> bool:
    """Two rig settings name the same file (a relative and an absolute path to it are the same rig)."""
    if a == b:
        return True
    if not isinstance(a, str) or not isinstance(b, str):
        return False
    return Path(a).resolve() == Path(b).resolve()


def stored_config(path: Path) -> dict[str, Any]:
    """A run's stored ``paired_config.json``; a key an older run's file lacks had its present default then
    (new settings default to the old behaviour)."""
    return {**_config_defaults(), **read_json_object(path)}


def settings_diff(have: dict[str, Any], want: dict[str, Any], keys: Iterable[str]) -> list[str]:
    """The ``keys`` whose settings differ between two configs (JSON form); rigs compare by the file."""
    return sorted(
        k for k in keys if have.get(k) != want.get(k) and not (k == "rig" and same_rig(have.get(k), want.get(k)))
    )
