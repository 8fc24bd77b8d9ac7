"""Tasks are files: ``configs/tasks/<name>.yaml`` (packaged) or any path; loaded, validated, ready to simulate.

    task = load_task("sort_cubes")            # a packaged task, by name
    task = load_task("my_lab/pour.yaml")      # a user's file
    problems = check_task_file("pour.yaml")   # every problem, one line each (``pilworld task check``)

The schema is :mod:`simrig.tasks.schema` (documented in docs/tasks.md); :class:`Task` is what the simulator
builds its scene, layout and checker from. Nothing here is specific to a task.
"""

from __future__ import annotations

import functools
import hashlib
import re
from pathlib import Path

import yaml

from pilworld.config.loader import ConfigError
from simrig.files import TASKS_DIR
from simrig.tasks.base import Layout, ObjectPose, PlacementCheck
from simrig.tasks.checks import build_problems, check_task
from simrig.tasks.errors import validation_lines
from simrig.tasks.mesh import MeshError
from simrig.tasks.schema import TaskFile
from simrig.tasks.task import Task

# The paper's three tasks: the default set of the demo and the benchmarks.
PAPER_TASKS = ("sort_cubes", "stack_bowls", "stack_blocks")
TASK_NAMES = PAPER_TASKS
MAX_FILE_BYTES = 1_000_000


class _Loader(yaml.SafeLoader):
    """YAML 1.2 booleans: only true/false. YAML 1.1 also reads on/off/yes/no as booleans, and ``on:`` is a
    predicate here."""


_Loader.yaml_implicit_resolvers = {
    key: [(tag, regexp) for tag, regexp in resolvers if tag != "tag:yaml.org,2002:bool"]
    for key, resolvers in yaml.SafeLoader.yaml_implicit_resolvers.items()
}
_Loader.add_implicit_resolver(
    "tag:yaml.org,2002:bool", re.compile(r"^(?:true|True|TRUE|false|False|FALSE)$"), list("tTfF")
)


class TaskFileError(ConfigError):
    """A task file is missing or invalid; ``problems`` holds one line per problem, each naming file and field."""

    def __init__(self, problems: list[str]) -> None:
        self.problems = problems
        more = (
            f" (and {len(problems) - 1} more problem(s): pilworld task check FILE lists them)"
            if len(problems) > 1
            else ""
        )
        super().__init__(problems[0] + more)


def packaged_tasks() -> tuple[str, ...]:
    """Names of the packaged task files (``simrig/tasks/files/``; ``configs/tasks/`` links to it)."""
    return tuple(sorted(p.stem for p in TASKS_DIR.glob("*.yaml")))


def task_path(task: str | Path) -> Path:
    """The file ``task`` names: a path (``.yaml``/``.yml`` or an existing file) or a packaged task's name."""
    text = str(task)
    path = Path(text).expanduser()
    if path.suffix.lower() in (".yaml", ".yml") or path.is_file() or "/" in text:
        if not path.is_file():
            raise TaskFileError([f"{path}: task file not found"])
        return path
    packaged = TASKS_DIR / f"{text}.yaml"
    if packaged.is_file():
        return packaged
    names = ", ".join(packaged_tasks())
    raise TaskFileError([f"task: no packaged task called {text!r} (packaged: {names}; or give a path to a .yaml file)"])


def _read(path: Path) -> tuple[dict[str, object], bytes]:
    try:
        raw = path.read_bytes()
    except OSError as exc:
        raise TaskFileError([f"{path}: cannot read the task file: {exc.strerror}"]) from None
    if len(raw) > MAX_FILE_BYTES:
        raise TaskFileError([f"{path}: {len(raw)} bytes; a task file is at most {MAX_FILE_BYTES} bytes"])
    try:
        data = yaml.load(raw.decode("utf-8"), Loader=_Loader)
    except UnicodeDecodeError:
        raise TaskFileError([f"{path}: not a text file (a task file is UTF-8 YAML)"]) from None
    except yaml.YAMLError as err:
        mark = getattr(err, "problem_mark", None)
        where = f" at line {mark.line + 1}" if mark is not None else ""
        raise TaskFileError([f"{path}: not valid YAML{where}: {getattr(err, 'problem', err)}"]) from None
    if data is None:
        raise TaskFileError(
            [f"{path}: the file is empty (a task file is a YAML mapping: name, instruction, subtasks, …)"]
        )
    if not isinstance(data, dict):
        raise TaskFileError([f"{path}: expected a mapping (name, instruction, subtasks, …), got {type(data).__name__}"])
    return data, raw


def _problems(path: Path) -> tuple[list[str], Task | None]:
    from pydantic import ValidationError

    data, raw = _read(path)
    try:
        spec = TaskFile.model_validate(data, context={"base_dir": path.resolve().parent})
    except ValidationError as err:
        return validation_lines(str(path), err), None
    built = [f"{path}: field '{p.field}': {p.message}" for p in build_problems(spec)]
    if built:
        return built, None
    try:
        task = Task(spec, path=path, digest=_digest(raw, spec))
    except (MeshError, ValueError) as exc:  # not expected after build_problems; still one line
        return [f"{path}: field 'objects': {exc}"], None
    lines = [f"{path}: field '{p.field}': {p.message}" for p in check_task(spec, task.geometry, draw=task.layout)]
    return lines, (None if lines else task)


def _digest(raw: bytes, spec: TaskFile) -> str:
    """sha256 of the file and of every mesh or texture file it names (a changed mesh is a changed task)."""
    h = hashlib.sha256(raw)
    for o in spec.objects:
        for name in (getattr(o, "file", None), o.texture.image if o.texture is not None else None):
            if name:
                h.update(Path(name).read_bytes())
    return h.hexdigest()


def check_task_file(task: str | Path) -> list[str]:
    """Every problem of a task file, one line each naming the file and the field ([] when it is valid)."""
    try:
        path = task_path(task)
        return _problems(path)[0]
    except TaskFileError as exc:
        return exc.problems


@functools.lru_cache(maxsize=64)
def _load_cached(path: str, mtime_ns: int, size: int) -> Task:
    problems, task = _problems(Path(path))
    if task is None:
        raise TaskFileError(problems)
    return task


def load_task(task: str | Path | Task) -> Task:
    """The task ``task`` names (a packaged name or a path), validated; :class:`TaskFileError` otherwise."""
    if isinstance(task, Task):
        return task
    path = task_path(task)
    st = path.stat()
    return _load_cached(str(path.resolve()), st.st_mtime_ns, st.st_size)


def make_task(task: str | Path | Task) -> Task:
    """Alias of :func:`load_task` (the simulator's entry point)."""
    return load_task(task)


__all__ = [
    "PAPER_TASKS",
    "TASKS_DIR",
    "TASK_NAMES",
    "Layout",
    "ObjectPose",
    "PlacementCheck",
    "Task",
    "TaskFileError",
    "check_task_file",
    "load_task",
    "make_task",
    "packaged_tasks",
    "task_path",
]
