"""``pilworld imagine``: only the imagined branch, from stored starts — many subtasks, no robot time.

For each stored start (a scene: task, subtask, layout seed) × checkpoint, the policy runs in closed
loop against the world model exactly as in a paired run's imagined branch
(:func:`pilworld.paired.imagined_branch.run_imagined`): the same start, checkpoint and seed give the same
episode, bit for bit. Episodes are stored like a paired run's (origin imagined, ``extra.pair`` the pair
id a paired run would give) and judged by the same judges, so their verdicts are the "imagined-only"
predictions prediction-powered inference (:mod:`pilworld.ppi`) combines with a paired run's.

Rollouts fan out over worker processes (``workers``) or a Ray cluster (``ray``,
:mod:`pilworld.imagine.ray_backend`); episodes are written by this process in plan order as they come
back, so every backend writes the same dataset. A killed run resumes: a rerun skips every pair stored.
"""

from __future__ import annotations

import contextlib
import dataclasses
import json
import time
from collections.abc import Callable, Iterator, Sequence
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

from tqdm import tqdm

from pilworld.config.rig import RigConfig
from pilworld.data.backup import back_up
from pilworld.data.episode import Episode
from pilworld.data.writer import EpisodeWriter
from pilworld.io.atomic import write_json
from pilworld.paired.revalidate import damaged_branches, restore_run, take_out
from pilworld.paired.runner import (
    RESUME_HINT,
    PairedConfig,
    PairedSubtask,
    branch_record,
    check_checkpoints,
    settings_diff,
    stored_branches,
    stored_config,
)
from pilworld.policies.base import PolicyError
from pilworld.starts.sources import StartsSource, load_starts
from pilworld.starts.store import StartsError, robot_spec_from_json, robot_spec_json
from pilworld.types import ChunkSpec, RobotSpec
from simrig.files import SIM_RIG
from simrig.tasks import Task

CONFIG_FILE = "imagine_config.json"


TIMINGS_FILE = "imagine_timings.jsonl"


@dataclass
class ImagineConfig:
    """Everything that decides an imagined-only run's episodes (stored in ``imagine_config.json``)."""

    starts: str  # a starts folder, a paired run or an episode store (pilworld.starts.sources)
    checkpoints: list[str]
    out: str
    rig: str = ""  # "" = the rig the starts were recorded on (starts.json), else the simulated rig
    world_model: str = ""  # a model folder; "" = the packaged checkpoint
    adapter: str = "auto"
    steps: int | None = None
    video_mode: str = "lossless"
    spec: ChunkSpec | None = (
        None  # None = the chunk timing the starts were recorded for (starts.json), else the default
    )
    start_frame: int | None = None  # a plain dataset's start frame (default H_h)
    count: int | None = None  # the first ``count`` scenes of the source; None = all
    # The task files of the starts' tasks (names or paths, comma-separated; "" = the packaged task of each
    # name): what a scripted checkpoint acts on, and whose hash the episodes record.
    task: str = ""
    instruction: str = ""  # the instruction given to the policy and recorded; "" = each start's own

    def __post_init__(self) -> None:
        from pilworld.collection.tasks import check_instruction

        check_checkpoints(self.checkpoints)
        if self.count is not None and self.count < 1:
            raise ValueError(f"count: expected at least 1 start, got {self.count}")
        check_instruction(self.instruction, "instruction")

    @property
    def task_files(self) -> dict[str, Task]:
        """The tasks given (``task``), by name; {} when none was."""
        from pilworld.collection.tasks import resolve_tasks

        return {t.name: t for t in resolve_tasks(self.task, what="task")} if self.task.strip() else {}

    def to_json(self) -> dict[str, Any]:
        d = asdict(self)
        d.pop("out")
        d.pop("count")  # more starts extend a run, as more subtasks extend a paired one
        return d

    @property
    def resolved_spec(self) -> ChunkSpec:
        if self.spec is None:
            raise ValueError("spec: not resolved yet (imagine_run takes it from the starts)")
        return self.spec

    def paired(self, task: str) -> PairedConfig:
        """The paired-run settings an imagined branch of ``task`` runs under (model, adapter, spec)."""
        return PairedConfig(
            rig=self.rig,
            task=task,
            checkpoints=list(self.checkpoints),
            subtasks=1,
            out=self.out,
            world_model=self.world_model,
            adapter=self.adapter,
            steps=self.steps,
            video_mode=self.video_mode,
            spec=self.resolved_spec,
        )


@dataclass(frozen=True)
class ImagineJob:
    """One imagined branch to run: a start (by its folder and episode) and a checkpoint."""

    order: int  # position in the plan: episodes are written in this order
    pair_id: str
    start_id: str
    checkpoint: str
    starts_root: str
    episode_index: int
    start_frame: int | None
    seed: int


@dataclass(frozen=True)
class JobResult:
    order: int
    episode: Episode
    seconds: float
    record: dict[str, Any]


def plan_jobs(cfg: ImagineConfig, source: StartsSource) -> list[ImagineJob]:
    """Every (scene, checkpoint) of the run, scenes in stored order, checkpoints as listed."""
    scenes = source.scenes()[: cfg.count] if cfg.count else source.scenes()
    jobs: list[ImagineJob] = []
    for sid in scenes:
        for ckpt in cfg.checkpoints:
            stored = source.pick(sid, ckpt)
            pair = PairedSubtask(ckpt, stored.subtask)
            jobs.append(
                ImagineJob(
                    len(jobs),
                    pair.pair_id,
                    sid,
                    ckpt,
                    str(source.root),
                    stored.episode_index,
                    cfg.start_frame,
                    pair.seed,
                )
            )
    return jobs


def check_start_tasks(cfg: ImagineConfig, source: StartsSource) -> None:
    """Every task the starts hold must be known where a checkpoint needs it, and each task file given must be
    the one the starts were recorded with (when they recorded its hash)."""
    from pilworld.collection.tasks import task_for_name
    from pilworld.paired.runner import is_server

    given = cfg.task_files
    names = sorted({s.subtask.task for s in source.starts})
    absent = sorted(set(given) - set(names))
    if absent:
        raise ValueError(f"task: the starts in {source.root} hold no start of task {absent[0]!r} (they hold {names})")
    scripted = [c for c in cfg.checkpoints if not is_server(c)]
    for stored in source.starts:
        name = stored.subtask.task
        task = task_for_name(name, given)
        if task is None:
            if scripted:
                raise ValueError(
                    f"task: the starts hold task {name!r}, which is no packaged task; give its task file with "
                    f"--task (the scripted checkpoint {scripted[0]} acts on it)"
                )
            continue
        if stored.task_sha256 and stored.task_sha256 != task.digest:
            where = f"{task.path}" if name in given else f"the packaged task {name!r}"
            raise ValueError(
                f"task: {where} is not the task file the starts of {name!r} were recorded with (its sha256 "
                f"{task.digest[:12]}… differs from the recorded {stored.task_sha256[:12]}…); give that file with --task"
            )


def robot_spec_for(cfg: ImagineConfig, source: StartsSource, rig: RigConfig | None = None) -> RobotSpec:
    """The limits the imagined branch's safety filter applies: the recording robot's, else the rig's
    (``rig``: ``cfg.rig`` already loaded)."""
    if source.meta is not None:
        return robot_spec_from_json(source.meta["robot_spec"])
    rig = rig if rig is not None else RigConfig.load(cfg.rig)
    if rig.hardware is not None:
        raise StartsError(
            f"--starts: {source.root} does not say which robot recorded it; on a hardware rig record starts "
            "with pilworld paired record-starts"
        )
    from simrig.robot import SimRobot

    return SimRobot(rig, "sort_cubes").spec  # the simulated rig's limits (building it connects nothing)


def _check_config(root: Path, cfg: ImagineConfig, *, write: bool) -> None:
    path = root / CONFIG_FILE
    want = json.loads(json.dumps(cfg.to_json()))
    if path.is_file():
        from pilworld.io.run_folder import read_json_object

        have = {**want, **read_json_object(path)}
        diff = settings_diff(have, want, set(have) | set(want))
        if diff:
            raise ValueError(
                f"{root}: holds an imagined-only run with different settings ({', '.join(diff)}); "
                "use another --out folder, or the same arguments to resume"
            )
        want["rig"] = have["rig"]
    if (root / "paired_config.json").is_file():
        raise ValueError(f"{root}: holds a paired run; write imagined-only runs to a folder of their own")
    if write:
        root.mkdir(parents=True, exist_ok=True)
        write_json(path, want)
        back_up(root, [CONFIG_FILE])


def check_paired_source(cfg: ImagineConfig, source: StartsSource) -> None:
    """A paired run's starts rerun its imagined branches only under its chunk timing and rig."""
    if source.kind != "paired":
        return
    have = stored_config(source.root.parent / "paired_config.json")
    want = {"rig": cfg.rig, "spec": json.loads(json.dumps(asdict(cfg.resolved_spec)))}
    diff = settings_diff(have, want, ("rig", "spec"))
    if diff:
        raise ValueError(f"--starts: {source.root.parent} was run with other settings ({', '.join(diff)})")


# ---------------------------------------------------------------------------------------------- workers

_WORKER: dict[str, Any] = {}


def _worker_state(cfg_json: dict[str, Any], robot: dict[str, Any]) -> dict[str, Any]:
    """This process's world models (per task), policies, control-video renderer and open start stores."""
    key = json.dumps([cfg_json, robot], sort_keys=True)
    if _WORKER.get("key") != key:
        from pilworld.control_video.gamma import ControlVideo

        cfg = config_from_json(cfg_json)
        rig = RigConfig.load(cfg.rig)
        _WORKER.clear()
        _WORKER.update(
            key=key,
            cfg=cfg,
            rig=rig,
            robot=robot_spec_from_json(robot),
            gamma=ControlVideo.from_rig(rig, cfg.resolved_spec),
            models={},
            policies={},
            stores={},
        )
    return _WORKER


def config_from_json(d: dict[str, Any], out: str = "") -> ImagineConfig:
    d = dict(d)
    d["spec"] = ChunkSpec(**d["spec"]) if d.get("spec") else None
    return ImagineConfig(out=out, **d)


def run_job(job: ImagineJob, cfg_json: dict[str, Any], robot: dict[str, Any]) -> JobResult:
    """One imagined branch, in whichever process runs it (inline, a worker process, a Ray worker)."""
    from pilworld.collection.tasks import task_extra, task_for_name
    from pilworld.data.reader import EpisodeStore
    from pilworld.paired.imagined_branch import branch_episode, run_imagined
    from pilworld.paired.runner import is_server, load_model
    from pilworld.policies.registry import make_policy
    from pilworld.starts.store import start_from_episode

    w = _worker_state(cfg_json, robot)
    cfg: ImagineConfig = w["cfg"]
    if job.starts_root not in w["stores"]:
        w["stores"][job.starts_root] = EpisodeStore(job.starts_root)
    store = w["stores"][job.starts_root]
    stored = start_from_episode(
        store.load(job.episode_index),
        f"{job.starts_root} episode {job.episode_index}",
        start_frame=job.start_frame,
        history=cfg.resolved_spec.history,
        fps=float(store.fps),
        episode_index=job.episode_index,
    )
    task = stored.subtask.task
    if "tasks" not in w:
        w["tasks"] = cfg.task_files
    task_file = task_for_name(task, w["tasks"])
    if task not in w["models"]:
        w["models"][task] = load_model(cfg.paired(task), w["rig"], task)
    model, adapter = w["models"][task]
    # A policy server's client serves every task; a scripted checkpoint acts on the task file it is given.
    key = (job.checkpoint, "" if is_server(job.checkpoint) else task)
    if key not in w["policies"]:
        w["policies"][key] = make_policy(job.checkpoint, w["rig"], cfg.resolved_spec, task=task_file)
    start = stored.start
    if cfg.instruction:  # the run's instruction replaces the recorded one (sent to the policy and stored)
        start = dataclasses.replace(start, subtask=dataclasses.replace(start.subtask, instruction=cfg.instruction))
    try:
        rollout = run_imagined(
            model,
            w["gamma"],
            cfg.resolved_spec,
            w["robot"],
            w["policies"][key],
            start,
            seed=job.seed,
            steps=cfg.steps,
            control_rate_hz=w["rig"].control_rate_hz,
        )
    except PolicyError as err:  # every branch stored so far stays; a rerun resumes from this one (CLI: exit 1)
        # The failed client is closed for good: a worker that lives on (in-process reruns, a Ray actor)
        # must connect afresh for its next job rather than fail it with "connection closed".
        failed = w["policies"].pop(key, None)
        close = getattr(failed, "close", None)
        if callable(close):
            with contextlib.suppress(Exception):
                close()
        raise err.in_context(job.checkpoint, f"{job.pair_id}, imagined branch", RESUME_HINT) from err
    if task_file is not None:
        fields = task_extra(task_file)
    else:  # a task known by its name only (a policy server needs no task file)
        fields = {"task": task, **({"task_sha256": stored.task_sha256} if stored.task_sha256 else {})}
    extra = {
        "pair": job.pair_id,
        **fields,
        "adapter": adapter or "",
        "world_model": cfg.world_model or "packaged",
        "start_id": stored.start_id,
        "starts": job.starts_root,
    }
    ep = branch_episode(rollout, checkpoint=job.checkpoint, seed=job.seed, extra=extra)
    return JobResult(job.order, ep, rollout.seconds, branch_record(job.pair_id, rollout))


def _run_job_args(args: tuple[ImagineJob, dict[str, Any], dict[str, Any]]) -> JobResult:
    return run_job(*args)


Backend = Callable[[Sequence[ImagineJob], dict[str, Any], dict[str, Any]], Iterator[JobResult]]


def local_backend(workers: int) -> Backend:
    """Inline (``workers`` ≤ 1) or over spawned worker processes; results in plan order."""
    from pilworld.collection.workers import process_map

    def run(jobs: Sequence[ImagineJob], cfg_json: dict[str, Any], robot: dict[str, Any]) -> Iterator[JobResult]:
        yield from process_map(_run_job_args, [(j, cfg_json, robot) for j in jobs], min(workers, len(jobs)) or 1)

    return run


# ---------------------------------------------------------------------------------------------- the run


def imagine_run(
    cfg: ImagineConfig,
    *,
    workers: int = 1,
    backend: Backend | None = None,
    progress: bool = True,
    on_episode: Callable[[str], None] | None = None,
) -> dict[str, Any]:
    """Run (or resume) an imagined-only run; returns a summary. ``backend`` overrides ``workers``."""
    from pilworld.collection.collect import dataset_spec
    from pilworld.io.run_folder import IMAGINED, check_out_folder
    from pilworld.paired.runner import load_model

    root = Path(cfg.out)
    check_out_folder(root, IMAGINED)  # a folder another command made is refused before anything else
    restore_run(root)  # a damaged table or setting of a stored run comes back from its backup first
    history = cfg.spec.history if cfg.spec is not None else ChunkSpec().history
    source = load_starts(cfg.starts, history=history, start_frame=cfg.start_frame)
    if not cfg.rig:
        cfg = dataclasses.replace(cfg, rig=str((source.meta or {}).get("rig") or SIM_RIG))
    if cfg.spec is None:
        chunk = (source.meta or {}).get("chunk")
        cfg = dataclasses.replace(cfg, spec=ChunkSpec(**chunk) if chunk else ChunkSpec())
    rig = RigConfig.load(cfg.rig)
    spec = cfg.resolved_spec
    check_paired_source(cfg, source)
    check_start_tasks(cfg, source)
    robot = robot_spec_for(cfg, source, rig)
    for task in sorted({s.subtask.task for s in source.starts}):
        load_model(cfg.paired(task), rig, task)  # a model that does not fit the rig fails before anything is written
    from pilworld.collection.tasks import task_for_name
    from pilworld.policies.registry import make_policy

    given = cfg.task_files
    first = task_for_name(source.starts[0].subtask.task, given) if source.starts else None
    for ckpt in cfg.checkpoints:
        try:  # a policy server that does not answer fails here, naming it, before anything is written
            make_policy(ckpt, rig, spec, task=first)
        except PolicyError as err:
            raise err.in_context(ckpt, "connecting", "nothing was written") from err
    _check_config(root, cfg, write=False)
    jobs = plan_jobs(cfg, source)
    done = stored_branches(root)
    redo = damaged_branches(root)  # stored branches whose files were lost: run again into their old slots
    take_out(done, redo)
    todo = [j for j in jobs if "imagined" not in done.get(j.pair_id, set())]
    _check_config(root, cfg, write=True)
    cfg_json = json.loads(json.dumps(cfg.to_json()))
    cfg_json["count"] = None
    robot_json = robot_spec_json(robot)
    run = backend or local_backend(workers)
    t_start = time.monotonic()
    seconds: list[float] = []
    bar = tqdm(
        total=len(jobs), initial=len(jobs) - len(todo), desc="imagined subtasks", unit="branch", disable=not progress
    )
    if todo:
        with EpisodeWriter(root, dataset_spec(rig, cfg.video_mode, spec)) as writer:
            for result in run(todo, cfg_json, robot_json):
                slot = redo.get((str(result.episode.extra["pair"]), "imagined"))
                if slot is None:
                    writer.append(result.episode)
                else:
                    writer.replace(slot, result.episode)
                seconds.append(result.seconds)
                with (root / TIMINGS_FILE).open("a") as fh:
                    fh.write(json.dumps(result.record) + "\n")
                back_up(root, [TIMINGS_FILE])
                if on_episode is not None:
                    on_episode(result.episode.extra["pair"])
                bar.update(1)
    bar.close()
    from pilworld.data.info import dataset_info

    return {
        "out": str(root),
        "starts": str(source.root),
        "scenes": len({j.start_id for j in jobs}),
        "branches_planned": len(jobs),
        "branches_run": len(seconds),
        "seconds": round(time.monotonic() - t_start, 2),
        "seconds_per_branch": round(sum(seconds) / len(seconds), 3) if seconds else None,
        "dataset": dataset_info(root) if (root / "meta" / "info.json").is_file() else None,
    }
