"""``pilworld sim collect``: whole episodes of scripted checkpoints on the simulated rig → episode store.

A *run* is one physical episode: a task laid out for a seed, the checkpoint working through every
subtask back to back (R rounds each, no reset in between), each subtask judged by the privileged
checker when its rounds end. It is stored as one episode per subtask (``subtask_index``, the
checker's verdict in ``meta/outcomes.parquet`` as judge ``sim_checker``), so success and failure
labels attach to exactly the frames they describe; the parts of a run share ``extra.run``.

Runs are spread over worker processes (each with its own MuJoCo and EGL context); the parent alone
writes. Rerunning the same command resumes: runs already stored are skipped, and a run cut short by
a kill is simulated again (it is deterministic) and only its missing parts are appended.
"""

from __future__ import annotations

import json
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
from tqdm import tqdm

from pilworld.collection.workers import process_map, worker_count, worker_robot
from pilworld.config.rig import RigConfig
from pilworld.data.episode import Episode
from pilworld.data.outcomes import Outcome, record_outcomes
from pilworld.data.reader import EpisodeStore
from pilworld.data.spec import DatasetSpec
from pilworld.data.writer import EpisodeWriter
from pilworld.types import ChunkSpec, Subtask

if TYPE_CHECKING:
    from simrig.tasks import Task

JUDGE_ID = "sim_checker"


@dataclass(frozen=True)
class RunJob:
    task: str  # the task's name (it keys the run)
    checkpoint: str
    seed: int
    source: str | Task | None = None  # the task file's path (or the task) when not a packaged name
    instruction: str = ""  # the instruction given to the policy and recorded; "" = the task's own
    appearance: str = "flat"

    @property
    def run_id(self) -> str:
        return f"{self.task}/{self.checkpoint}/{self.seed}"


@dataclass(frozen=True)
class PartResult:
    """One subtask of a run, ready to write (numpy arrays only: it crosses a process boundary)."""

    job: RunJob
    subtask_index: int
    num_subtasks: int
    instruction: str
    images: dict[str, np.ndarray]
    state: np.ndarray
    action: np.ndarray
    rounds: np.ndarray
    success: bool
    reason: str
    task_fields: dict[str, Any] = field(default_factory=dict)  # extra.task, task_sha256 (and sim_task)


def simulate_run(rig_path: str, job: RunJob, spec: ChunkSpec) -> list[PartResult]:
    """Simulate one run (all subtasks back to back) and return its parts."""
    from pilworld.collection.rollout import run_subtask
    from pilworld.collection.tasks import task_extra
    from pilworld.policies.scripted import ScriptedPolicy

    robot = worker_robot(rig_path, job.source if job.source is not None else job.task, job.appearance)
    # Given its task file, a scripted checkpoint acts on that task whatever the instruction says.
    policy = ScriptedPolicy(robot.rig, job.checkpoint, horizon=spec.horizon, task=robot.task)
    start = robot.reset(seed=job.seed, subtask=0, history=spec.history, stride=spec.stride)
    obs = start.observation
    parts = []
    n = robot.task.num_subtasks
    instruction = job.instruction or robot.task.instruction
    fields = task_extra(robot.task)
    # One continuous episode: the policy keeps its memory across subtask boundaries (a gripper may be
    # half open when a window ends); only the checker's windows are per subtask.
    policy.reset(seed=job.seed * 100)
    for k in range(n):
        robot.subtask = Subtask(robot.task.name, k, instruction, job.seed)
        rec = run_subtask(robot, policy.infer, obs, instruction, spec=spec, subtask_index=k)
        assert rec.check is not None and rec.last is not None
        parts.append(
            PartResult(
                job=job,
                subtask_index=k,
                num_subtasks=n,
                instruction=instruction,
                images={v: np.stack(frames) for v, frames in rec.images.items()},
                state=np.stack(rec.states),
                action=np.stack(rec.actions),
                rounds=np.asarray(rec.rounds, dtype=np.int64),
                success=rec.check.success,
                reason=rec.check.reason,
                task_fields=fields,
            )
        )
        obs = rec.last  # the next subtask continues from here; no second render
    return parts


def _worker(args: tuple[str, RunJob, ChunkSpec]) -> list[PartResult]:
    return simulate_run(*args)


def dataset_spec(rig_path: str | RigConfig, video_mode: str, spec: ChunkSpec) -> DatasetSpec:
    """The episode store's spec for ``rig_path`` (a rig file, or the rig already loaded) at ``spec``'s stride."""
    rig = rig_path if isinstance(rig_path, RigConfig) else RigConfig.load(rig_path)
    fps = rig.control_rate_hz / spec.stride
    if abs(fps - round(fps)) > 1e-9:
        raise ValueError(f"control rate {rig.control_rate_hz} Hz / stride {spec.stride} is not an integer frame rate")
    size = (rig.image_size.height, rig.image_size.width)
    return DatasetSpec(
        fps=round(fps), views={v: size for v in rig.cameras}, video_mode=video_mode, steps_per_frame=spec.stride
    )


def stored_parts(root: Path) -> dict[str, set[int]]:
    """Run id → subtask indices already in the dataset at ``root``."""
    if not (root / "meta" / "info.json").is_file():
        return {}
    done: dict[str, set[int]] = {}
    for row in EpisodeStore(root).episodes:
        run = _extra(row).get("run")
        if run:
            done.setdefault(str(run), set()).add(int(row["subtask_index"]))
    return done


def _extra(row: dict[str, Any]) -> dict[str, Any]:
    raw = row.get("extra")
    return dict(json.loads(raw)) if raw else {}


def plan_jobs(
    tasks: Sequence[str | Task],
    checkpoints: Sequence[str],
    episodes: int,
    seed0: int,
    *,
    instruction: str = "",
    appearance: str = "flat",
) -> list[RunJob]:
    """``episodes`` runs per task and checkpoint; ``tasks`` are packaged names or loaded tasks."""
    from pilworld.collection.tasks import task_ref

    jobs = []
    for t in tasks:
        name, source = (t, None) if isinstance(t, str) else (t.name, task_ref(t))
        jobs += [
            RunJob(name, c, seed0 + i, source, instruction, appearance) for c in checkpoints for i in range(episodes)
        ]
    return jobs


def collect(
    out: str | Path,
    *,
    rig_path: str,
    tasks: Sequence[str | Path | Task],
    checkpoints: Sequence[str],
    episodes: int,
    seed0: int = 0,
    workers: int | None = None,
    video_mode: str = "h264",
    spec: ChunkSpec | None = None,
    progress: bool = True,
    instruction: str = "",
    appearance: str = "flat",
) -> dict[str, Any]:
    """Collect ``episodes`` runs per task × checkpoint into ``out``; returns a summary (counts, time).

    ``tasks`` are packaged names, task files or loaded tasks; ``instruction`` (non-empty) replaces each
    task's own as the instruction given to the policy and recorded."""
    import time

    from pilworld.collection.tasks import require_simulated, resolve_tasks
    from pilworld.policies.registry import policy_names

    spec = spec or ChunkSpec()
    root = Path(out)
    # Everything is checked before the folder is created or touched.
    loaded = resolve_tasks(list(tasks))
    require_simulated(loaded)
    bad = [c for c in checkpoints if c not in policy_names()]
    if bad or not checkpoints:
        raise ValueError(
            f"checkpoint: not a scripted checkpoint: {bad or list(checkpoints)} (known: {', '.join(policy_names())})"
        )
    if not instruction.strip() and instruction:
        raise ValueError("instruction: must not be blank")
    from dataclasses import asdict

    from pilworld.data.writer import check_store_spec
    from pilworld.io.run_folder import COLLECTION, check_out_folder, claim

    check_out_folder(root, COLLECTION, legacy=True)  # a folder another command made is refused
    store_spec = dataset_spec(rig_path, video_mode, spec)
    check_store_spec(root, store_spec)
    done = stored_parts(root)
    jobs = plan_jobs(loaded, checkpoints, episodes, seed0, instruction=instruction, appearance=appearance)
    parts_of = {t.name: t.num_subtasks for t in loaded}
    todo = [j for j in jobs if j.run_id not in done or len(done[j.run_id]) < parts_of[j.task]]
    workers = worker_count(workers, len(todo))
    t0 = time.monotonic()
    written = 0
    claim(root, COLLECTION, {"rig": str(Path(rig_path).resolve()), "video_mode": video_mode, "spec": asdict(spec)})
    with EpisodeWriter(root, store_spec) as writer:
        bar = tqdm(total=len(todo), desc="runs", unit="run", disable=not progress)
        for parts in process_map(_worker, [(rig_path, j, spec) for j in todo], workers):
            have = done.get(parts[0].job.run_id, set())
            outcomes = []
            for p in parts:
                if p.subtask_index in have:
                    continue
                index = writer.append(_episode(p))
                outcomes.append(Outcome(index, JUDGE_ID, "sim_state", p.success, len(p.state)))
                written += 1
            if outcomes:
                record_outcomes(root, outcomes)
            bar.update(1)
        bar.close()
    summary = summarize(root)
    summary.update(
        {
            "runs_planned": len(jobs),
            "runs_simulated": len(todo),
            "parts_written": written,
            "seconds": round(time.monotonic() - t0, 1),
            "workers": workers,
        }
    )
    return summary


def _episode(p: PartResult) -> Episode:
    return Episode(
        images=p.images,
        state=p.state.astype(np.float32),
        action=p.action.astype(np.float32),
        task=p.instruction,
        origin="real",
        subtask_index=p.subtask_index,
        checkpoint=p.job.checkpoint,
        seed=p.job.seed,
        round_index=p.rounds,
        extra={
            "run": p.job.run_id,
            **(p.task_fields or {"task": p.job.task, "sim_task": p.job.task}),
            "parts": p.num_subtasks,
            "checker": p.reason,
            **({"appearance": p.job.appearance} if p.job.appearance != "flat" else {}),
        },
    )


def summarize(root: Path) -> dict[str, Any]:
    """Episodes, frames, bytes and success/failure counts per task and checkpoint of a collected set."""
    from pilworld.collection.tasks import episode_task_name
    from pilworld.data.info import disk_bytes
    from pilworld.data.outcomes import read_outcomes

    store = EpisodeStore(root)
    verdict = {o.episode_index: o.success for o in read_outcomes(root) if o.judge_id == JUDGE_ID}
    table: dict[str, dict[str, dict[str, int]]] = {}
    frames = 0
    for e, ep in enumerate(store.episodes):
        task = episode_task_name(_extra(ep), "?")
        row = table.setdefault(task, {}).setdefault(str(ep.get("checkpoint", "")), {"success": 0, "failure": 0})
        row["success" if verdict.get(e) else "failure"] += 1
        frames += int(ep["length"])
    return {
        "root": str(root),
        "episodes": store.num_episodes,
        "frames": frames,
        "bytes": disk_bytes(root),
        "success": sum(r["success"] for t in table.values() for r in t.values()),
        "failure": sum(r["failure"] for t in table.values() for r in t.values()),
        "per_task": table,
    }
