"""Tasks as the commands take them (packaged names or task files), and what an episode records about its task.

``--task`` takes ``all`` (the paper's three tasks), a packaged task's name, a path to a task file, or
several of these comma-separated. :func:`resolve_tasks` loads and validates every one before anything
runs; a task's *name* (its file's ``name:`` field) keys its episodes, pairs and metrics, so two files of
the same name in one run are refused.

Every episode records ``extra.task`` (the name) and ``extra.task_sha256`` (:attr:`Task.digest`: the file
and its mesh and texture files), plus ``extra.sim_task`` when the task is simulated, which older
readers and datasets use. Readers take ``task`` first and fall back to ``sim_task``
(:func:`episode_task_name`).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:  # imported where used: the command line reads APPEARANCES without loading the simulator
    from simrig.tasks import Task

# How the simulated scene looks (``SimRobot(..., appearance=...)``; simrig.appearance.APPEARANCES).
APPEARANCES = ("flat", "varied")
MAX_INSTRUCTION = 500  # characters, as in a task file


def resolve_tasks(value: str | Sequence[str | Path | Task], *, what: str = "task") -> list[Task]:
    """The tasks ``value`` names, loaded and validated; a one-line ``ValueError`` prefixed ``what`` otherwise."""
    from simrig.tasks import PAPER_TASKS, TaskFileError, load_task, packaged_tasks

    if isinstance(value, str):
        items: list[str | Path | Task] = (
            list(PAPER_TASKS) if value.strip() == "all" else [t.strip() for t in value.split(",") if t.strip()]
        )
    else:
        items = list(value)
    if not items:
        raise ValueError(f"{what}: expected a task name, a task file or 'all', got {value!r}")
    tasks: list[Task] = []
    for item in items:
        try:
            tasks.append(load_task(item))
        except TaskFileError as err:
            if isinstance(item, str) and err.problems[0].startswith("task: no packaged task"):
                # A name that is no packaged task (and no file): say so in the flag's words.
                names = ", ".join(packaged_tasks())
                raise ValueError(
                    f"{what}: unknown task {item!r} (packaged: {names}; or give a path to a task file, .yaml)"
                ) from None
            raise ValueError(f"{what}: {err}") from None
    seen: dict[str, Task] = {}
    for task in tasks:
        other = seen.get(task.name)
        if other is None:
            seen[task.name] = task
        elif other.digest == task.digest:
            raise ValueError(f"{what}: task {task.name!r} listed twice")
        else:
            raise ValueError(
                f"{what}: two task files are named {task.name!r} ({other.path} and {task.path}); a task's name "
                "keys its episodes, so give each task a name of its own"
            )
    return tasks


def not_simulated(task: Task) -> str:
    """The one-line reason a hardware-only task cannot run on the simulated rig."""
    where = f"{task.path}: " if task.path is not None else ""
    return f"{where}task {task.name!r} has no objects: the simulated rig cannot build it"


def require_simulated(tasks: Sequence[Task], *, what: str = "task") -> None:
    """Refuse hardware-only task files (no objects) where the simulated rig must build the scene."""
    for task in tasks:
        if not task.simulated:
            raise ValueError(f"{what}: {not_simulated(task)}")


def task_ref(task: Task) -> str | Task:
    """What names ``task`` across a process boundary: its file's path (loaded again there), else the task."""
    return str(task.path.resolve()) if task.path is not None else task


def task_extra(task: Task) -> dict[str, Any]:
    """The task fields of an episode's ``extra``: name and file hash, and ``sim_task`` for a simulated task."""
    extra: dict[str, Any] = {"task": task.name, "task_sha256": task.digest}
    if task.simulated:
        extra["sim_task"] = task.name  # what readers before task files look for
    return extra


def episode_task_name(extra: Mapping[str, Any] | None, default: str = "") -> str:
    """The task of a stored episode: ``extra.task``, else (older data) ``extra.sim_task``, else ``default``."""
    if not extra:
        return default
    for key in ("task", "sim_task"):
        value = extra.get(key)
        if isinstance(value, str) and value.strip():
            return value
    return default


def task_for_name(name: str, given: Mapping[str, Task] | None = None) -> Task | None:
    """The task called ``name``: one of ``given``, else the packaged task of that name, else None."""
    if given and name in given:
        return given[name]
    from simrig.tasks import load_task, packaged_tasks

    if name in packaged_tasks():
        return load_task(name)
    return None


def check_instruction(instruction: str | None, what: str = "instruction") -> str:
    """An instruction override: "" or None (none: each task's own), else one non-blank line of at most
    500 characters; returned as given ("" for None)."""
    if not instruction:
        return ""
    if not instruction.strip():
        raise ValueError(f"{what}: the instruction must not be blank")
    if "\n" in instruction or "\r" in instruction:
        raise ValueError(f"{what}: the instruction must be one line")
    if len(instruction) > MAX_INSTRUCTION:
        raise ValueError(f"{what}: at most {MAX_INSTRUCTION} characters, got {len(instruction)}")
    return instruction
