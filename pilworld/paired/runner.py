"""``pilworld paired run``: every subtask twice — on the robot and in the world model — from one start.

For each (checkpoint, subtask) pair the robot is brought to the subtask's start (on the simulated rig:
``SimRobot.reset(seed, subtask)``, which lays out the task with the earlier subtasks done and records
the H_h history frames), then

1. the **imagined branch** runs the policy in closed loop against the world model, starting from that
   start observation and its real history (the robot stands still meanwhile);
2. the **real branch** runs the same policy, reset with the same seed, on the robot.

Both rollouts are appended to one dataset in the episode store with ``origin`` imagined / real and
``extra.pair`` naming the pair; the real branch's privileged checker verdict goes to the outcomes
table. Each episode is committed as soon as its branch finishes, so a killed run loses at most the
branch in flight; rerunning the same command skips every branch already stored and, since starts,
policies and the world model are all seeded, ends with the same dataset an uninterrupted run writes.
Wall times per branch go to ``paired_timings.jsonl`` beside the dataset (not into it: they differ
between runs).
"""

from __future__ import annotations

import contextlib
import json
import sys
import time
from collections.abc import Callable, Iterable, Iterator, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from tqdm import tqdm

from pilworld.config.rig import RigConfig
from pilworld.control_video.gamma import ControlVideo
from pilworld.data.backup import back_up
from pilworld.data.outcomes import record_outcomes
from pilworld.data.reader import EpisodeStore
from pilworld.data.writer import EpisodeWriter
from pilworld.envs import RobotEnv
from pilworld.io.atomic import write_json
from pilworld.paired.config import (
    CONFIG_FILE,
    TASK_HASHES,
    TIMINGS_FILE,
    UNCOMPARED,
    PairedConfig,
    check_checkpoints,
    settings_diff,
    stored_config,
)
from pilworld.paired.imagined_branch import branch_episode, run_imagined
from pilworld.paired.operator import Operator
from pilworld.paired.policy_metadata import honour_reset_poses, store_metadata
from pilworld.paired.real_source import RealBranchSource
from pilworld.paired.revalidate import damaged_branches, damaged_starts, restore_run, take_out
from pilworld.paired.stations import open_station
from pilworld.policies.base import Policy, PolicyError
from pilworld.policies.registry import make_policy
from pilworld.rollout import Rollout, closed_loop
from pilworld.starts.sources import PAIRED_STARTS
from pilworld.starts.store import StartsWriter, start_id
from pilworld.types import ChunkSpec, Start, Subtask
from pilworld.world_model.base import HistoryAblation, RigBound, WorldModel
from simrig.tasks import Task

# The runner's API, with the settings it re-exports from pilworld.paired.config.
__all__ = [
    "CONFIG_FILE",
    "JUDGE_ID",
    "ORIGINS",
    "RESUME_HINT",
    "TASK_HASHES",
    "TIMINGS_FILE",
    "PairedConfig",
    "PairedSubtask",
    "branch_record",
    "check_checkpoints",
    "check_station_tasks",
    "connect_policies",
    "connect_policy",
    "is_server",
    "load_model",
    "paired_run",
    "plan_subtasks",
    "rollout_length",
    "settings_diff",
    "stored_branches",
    "stored_config",
    "stored_slots",
]

ORIGINS = ("imagined", "real")
JUDGE_ID = "sim_checker"


@dataclass(frozen=True)
class PairedSubtask:
    """One pair: a policy checkpoint on one subtask (task, index, layout seed)."""

    checkpoint: str
    subtask: Subtask

    @property
    def pair_id(self) -> str:
        s = self.subtask
        return f"{s.task}/{self.checkpoint}/seed{s.seed}/subtask{s.index}"

    @property
    def seed(self) -> int:
        """The policy and world-model seed of this pair (the same in both branches)."""
        return self.subtask.seed * 100 + self.subtask.index


def plan_subtasks(
    task: str, count: int, seed0: int, checkpoints: Sequence[str], num_subtasks: int, instruction: str
) -> list[PairedSubtask]:
    """``count`` subtasks per checkpoint: subtask indices 0, 1, … of layout ``seed0``, then of ``seed0 + 1``, …"""
    plan = []
    for ckpt in checkpoints:
        for i in range(count):
            sub = Subtask(task=task, index=i % num_subtasks, instruction=instruction, seed=seed0 + i // num_subtasks)
            plan.append(PairedSubtask(ckpt, sub))
    return plan


def stored_slots(root: Path) -> dict[tuple[str, str], int]:
    """(pair id, origin) → episode index of every branch committed in the dataset at ``root``."""
    if not (root / "meta" / "info.json").is_file():
        return {}
    slots: dict[tuple[str, str], int] = {}
    for i, row in enumerate(EpisodeStore(root).episodes):
        extra = json.loads(row.get("extra") or "{}")
        if "pair" in extra:
            slots[(str(extra["pair"]), str(row.get("origin")))] = i
    return slots


def stored_branches(root: Path) -> dict[str, set[str]]:
    """Pair id → origins already committed in the dataset at ``root``."""
    done: dict[str, set[str]] = {}
    for pair, origin in stored_slots(root):
        done.setdefault(pair, set()).add(origin)
    return done


def _set_up_start(
    pair: PairedSubtask,
    have: set[str],
    starts: StartsWriter,
    slots: dict[tuple[str, str], int],
    redo: dict[tuple[str, str], int],
) -> Start | None:
    """On a rig whose scenes are set up by hand: the start a resumed pair must run from, or None for a new scene.

    Both branches of a pair run from one start, and a set-up scene cannot be repeated. A pair whose
    real branch is stored imagines from the stored start it ran from. A pair whose real branch is lost
    runs again from a new scene, both branches (the stored imagined one is rewritten in its slot), and
    ``have`` is emptied in place.
    """
    if not have:
        return None
    checkpoint = pair.checkpoint
    if "real" in have and (start_id(pair.subtask), checkpoint) in starts.stored():
        return starts.load(pair.subtask, checkpoint=checkpoint)
    for origin in sorted(have):
        redo.setdefault((pair.pair_id, origin), slots[(pair.pair_id, origin)])
    lost = "real branch" if "real" not in have else "start"
    print(
        f"{pair.pair_id}: its {lost} is lost and a set-up scene cannot be repeated; both branches run again "
        "from a new one",
        file=sys.stderr,
        flush=True,
    )
    have.clear()
    return None


def _check_config(root: Path, cfg: PairedConfig, tasks: Sequence[Task], *, write: bool = True) -> None:
    """Refuse a folder holding a run with other settings; with ``write``, claim the folder for ``cfg``.

    Besides the settings, the file hash of each task (``task_sha256``) is stored and compared: a task file
    edited since the run began is another task."""
    path = root / CONFIG_FILE
    want = json.loads(json.dumps(cfg.to_json()))
    want[TASK_HASHES] = {t.name: t.digest for t in tasks}
    if path.is_file():
        have = stored_config(path)
        keys = (set(have) | set(want)) - set(UNCOMPARED)
        if TASK_HASHES not in have:  # a run from before task files: its tasks were the packaged ones
            keys.discard(TASK_HASHES)
        diff = settings_diff(have, want, keys)
        if diff:
            raise ValueError(
                f"{root}: holds a paired run with different settings ({', '.join(diff)}); "
                "use another --out folder, or the same arguments to resume"
            )
        want["rig"] = have["rig"]  # keep the spelling the run was started with
    if write:
        root.mkdir(parents=True, exist_ok=True)
        write_json(path, want)
        back_up(root, [CONFIG_FILE])


def load_model(cfg: PairedConfig, rig: RigConfig, task: str) -> tuple[WorldModel, str | None]:
    """The world model for ``task`` (its adapter under ``adapter="auto"``), checked against the rig."""
    from pilworld.world_model import DEFAULT_CHECKPOINT
    from pilworld.world_model.base import WorldModelInfo
    from pilworld.world_model.loader import adapter_names, load_world_model

    path = Path(cfg.world_model) if cfg.world_model else Path(DEFAULT_CHECKPOINT)
    names = adapter_names(path)
    if cfg.adapter == "auto":
        adapter = task if task in names else None
    elif cfg.adapter == "none":
        adapter = None
    else:
        if cfg.adapter not in names:
            raise ValueError(f"adapter: {cfg.adapter!r} is not in {path} (has {names or 'none'})")
        adapter = cfg.adapter
    # What the rig records: a folder that does not say its views and sizes (a stock Wan2.1) predicts these.
    rig_info = WorldModelInfo(
        views=tuple(rig.cameras),
        height=rig.image_size.height,
        width=rig.image_size.width,
        future=cfg.spec.frames,
        history=cfg.spec.history,
    )
    model = load_world_model(path, adapter=adapter, info=rig_info)
    if isinstance(model, RigBound):  # a model that composites the rig's geometry (v2) uses this rig's calibration
        model.bind_rig(rig)
    if not cfg.history:
        if not isinstance(model, HistoryAblation):
            raise ValueError(f"history: the model in {path} has no history memory to hide")
        model = model.without_history()
    size = (rig.image_size.width, rig.image_size.height)
    if cfg.resize and (model.info.width, model.info.height) != size:
        from pilworld.world_model.resized import ResizedWorldModel

        model = ResizedWorldModel(model, height=size[1], width=size[0])
    info = model.info
    if set(info.views) != set(rig.cameras):
        raise ValueError(
            f"world model {path} predicts views {list(info.views)}, rig {rig.name!r} has {list(rig.cameras)}"
        )
    if (info.width, info.height) != (rig.image_size.width, rig.image_size.height):
        raise ValueError(
            f"world model {path} works at {info.width}x{info.height}, rig {rig.name!r} renders "
            f"{rig.image_size.width}x{rig.image_size.height} (resize=True runs it resized)"
        )
    if info.future != cfg.spec.frames:
        raise ValueError(
            f"world model {path} predicts K={info.future} frames per round, the run uses K={cfg.spec.frames}"
        )
    return model, adapter


def branch_record(pair_id: str, rollout: Rollout) -> dict[str, Any]:
    """One branch's line of the timings file (wall times per round; kept out of the dataset)."""
    return {
        "pair": pair_id,
        "origin": rollout.origin,
        "seconds": round(rollout.seconds, 4),
        "policy_ms": [round(t.policy_s * 1000, 2) for t in rollout.timings],
        "env_ms": [round(t.env_s * 1000, 2) for t in rollout.timings],
    }


RESUME_HINT = "branches already stored stay; rerun the same command to resume"


@contextlib.contextmanager
def _closing(policies: Iterable[Policy]) -> Iterator[None]:
    """Close remote policies' connections when the run ends, however it ends."""
    try:
        yield
    finally:
        for policy in policies:
            close = getattr(policy, "close", None)
            if callable(close):
                close()


def connect_policy(checkpoint: str, rig: RigConfig, spec: ChunkSpec, task: Task | None = None) -> Policy:
    """``make_policy``, with a policy server that cannot be reached named by its checkpoint."""
    try:
        return make_policy(checkpoint, rig, spec, task=task)
    except PolicyError as err:
        raise err.in_context(checkpoint, "connecting", RESUME_HINT) from err


def is_server(checkpoint: str) -> bool:
    return checkpoint.startswith(("ws://", "wss://"))


def connect_policies(
    checkpoints: Sequence[str], rig: RigConfig, spec: ChunkSpec, tasks: Sequence[Task]
) -> dict[tuple[str, str], Policy]:
    """(checkpoint, task name) → its policy: one client per policy server, shared by every task; a scripted
    checkpoint per task, since it acts on the task file it is given."""
    out: dict[tuple[str, str], Policy] = {}
    for c in checkpoints:
        shared = connect_policy(c, rig, spec, tasks[0])
        for k, t in enumerate(tasks):
            out[(c, t.name)] = shared if k == 0 or is_server(c) else connect_policy(c, rig, spec, t)
    return out


def check_station_tasks(
    rig: RigConfig, tasks: Sequence[Task], operator: Operator | None, *, what: str = "task"
) -> None:
    """Refuse a task the rig cannot run: the simulated rig builds every scene (a task file without objects
    cannot be built); on a hardware rig the operator lays each one out, but an unattended fake rig has
    nobody to do that for a task its simulator cannot build."""
    from pilworld.collection.tasks import not_simulated, require_simulated
    from pilworld.paired.operator import UnattendedOperator

    if rig.hardware is None:
        require_simulated(tasks, what=what)
    elif isinstance(operator, UnattendedOperator):
        for t in tasks:
            if not t.simulated:
                raise ValueError(
                    f"--unattended: {not_simulated(t)}, so nobody would lay it out or judge it; run it with an "
                    "operator at a terminal"
                )


def paired_run(
    cfg: PairedConfig,
    *,
    progress: bool = True,
    on_branch: Callable[[PairedSubtask, str], None] | None = None,
    operator: Operator | None = None,
    rig: RigConfig | None = None,
) -> dict[str, Any]:
    """Run (or resume) a paired run; returns a summary. ``on_branch`` is called after each stored branch;
    ``rig``: ``cfg.rig`` already loaded (the demo loads it once for the whole run).

    On a rig with a ``hardware:`` section the real branch runs on the robot (or its protocol fakes)
    through :class:`~pilworld.paired.stations.HardwareStation`; ``operator`` answers its prompts
    (default: the terminal).
    """
    from pilworld.collection.collect import dataset_spec
    from pilworld.collection.tasks import task_extra
    from pilworld.io.run_folder import PAIRED, check_out_folder

    root = Path(cfg.out)
    check_out_folder(root, PAIRED)  # a folder another command made is refused before anything else
    rig = rig if rig is not None else RigConfig.load(cfg.rig)
    tasks = cfg.task_files  # loads and validates every task file
    check_station_tasks(rig, tasks, operator)
    if rig.hardware is not None and cfg.appearance != "flat":
        raise ValueError(f"appearance: rig {rig.name!r} is a hardware rig; {cfg.appearance!r} is for the simulated rig")
    by_name = {t.name: t for t in tasks}
    restore_run(root)  # a damaged table or setting of a stored run comes back from its backup first
    models = {t.name: load_model(cfg, rig, t.name) for t in tasks}  # fails before anything is written
    store_spec = dataset_spec(rig, cfg.video_mode, cfg.spec)
    _check_config(root, cfg, tasks, write=False)
    plan: list[PairedSubtask] = []
    for t in tasks:
        plan += plan_subtasks(t.name, cfg.subtasks, cfg.seed, cfg.checkpoints, t.num_subtasks, cfg.instruction_for(t))
    slots = stored_slots(root)
    done = stored_branches(root)
    redo = damaged_branches(root)  # stored branches whose files were lost: run again into their old slots
    take_out(done, redo)
    restart = damaged_starts(root / PAIRED_STARTS)  # likewise its stored starts: recorded again
    scenes = {sid for sid, _ in restart}
    todo = [p for p in plan if done.get(p.pair_id, set()) != set(ORIGINS) or start_id(p.subtask) in scenes]
    need_real = [p for p in todo if "real" not in done.get(p.pair_id, set())]
    reference = RealBranchSource(cfg.real_from, cfg) if cfg.real_from and need_real else None
    missing = [p.pair_id for p in need_real if reference is not None and not reference.has(p.pair_id)]
    if missing:  # fail before anything is written, naming what to run first
        raise ValueError(
            f"real_from: {cfg.real_from} lacks the real branch of {len(missing)} pair(s), e.g. {missing[0]}"
        )
    # A hardware station checks its operator here (none at a terminal: a typed error), before any motion.
    station_ = open_station(cfg.rig, by_name, operator, appearance=cfg.appearance, rig=rig)
    gamma = ControlVideo.from_rig(rig, cfg.spec)
    # A policy server is reached (and a scripted checkpoint built) before the folder is claimed.
    by_task = connect_policies(cfg.checkpoints, rig, cfg.spec, tasks)
    policies = {c: by_task[(c, tasks[0].name)] for c in cfg.checkpoints}
    _check_config(root, cfg, tasks)  # claims the folder only now that every check passed
    store_metadata(root, policies)
    t_start = time.monotonic()
    records: list[dict[str, Any]] = []
    bar = tqdm(
        total=len(plan), initial=len(plan) - len(todo), desc="paired subtasks", unit="pair", disable=not progress
    )
    with (
        _closing({id(p): p for p in by_task.values()}.values()),
        station_ as station,
        EpisodeWriter(root, store_spec) as writer,
        StartsWriter(
            root / PAIRED_STARTS,
            dataset_spec(rig, "lossless", cfg.spec),
            station.robot.spec,
            cfg.spec,
            rig=cfg.rig,
            task_sha256={t.name: t.digest for t in tasks},
        ) as starts,
    ):
        robot = station.robot
        honour_reset_poses(station, policies)
        starts.redo(restart)
        for pair in todo:
            have = set(done.get(pair.pair_id, set()))
            sub = pair.subtask
            model, adapter = models[sub.task]
            policy = by_task[(pair.checkpoint, sub.task)]
            extra = {
                "pair": pair.pair_id,
                **task_extra(by_name[sub.task]),
                "adapter": adapter or "",
                "world_model": cfg.world_model or "packaged",
            }
            if not station.shared_starts and have == set(ORIGINS):
                # Both branches stored, only their start's files damaged: no branch needs it again, and
                # re-recording it would mean setting the scene up by hand for nothing.
                print(
                    f"{pair.pair_id}: its stored start is damaged; both branches are intact, so it is left as it is "
                    "(`pilworld imagine` cannot rerun this pair)",
                    file=sys.stderr,
                    flush=True,
                )
                bar.update(1)
                continue
            start = None if station.shared_starts else _set_up_start(pair, have, starts, slots, redo)
            fresh = start is None  # a new scene: stored with the first branch run from it
            if start is None:
                start = station.start(sub, pair.checkpoint, cfg.spec)
            if station.shared_starts:  # the same scene for every checkpoint, laid out bit for bit: stored once
                starts.add(start)
                fresh = False
            for origin in station.order:
                if origin in have:
                    continue
                if origin == "real" and reference is not None:
                    reference.copy(pair.pair_id, writer, root, index=redo.get((pair.pair_id, origin)))
                    if on_branch is not None:
                        on_branch(pair, origin)
                    continue
                try:
                    if origin == "imagined":
                        rollout = run_imagined(
                            model,
                            gamma,
                            cfg.spec,
                            robot.spec,
                            policy,
                            start,
                            seed=pair.seed,
                            steps=cfg.steps,
                            control_rate_hz=rig.control_rate_hz,
                        )
                    else:
                        policy.reset(seed=pair.seed)
                        env = RobotEnv(robot, cfg.spec, pace=station.pace)  # a simulator may run ahead of real time
                        rollout = closed_loop(policy, env, sub.instruction, cfg.spec.rounds, start=start)
                except PolicyError as err:  # the branch in flight is lost; every stored one stays
                    where = f"{sub.task} subtask {sub.index}, layout seed {sub.seed}, {origin} branch"
                    raise err.in_context(pair.checkpoint, where, RESUME_HINT) from err
                if fresh:  # after the branch ran (its first chunk's observation stays fresh), before it is stored
                    starts.add(start, checkpoint=pair.checkpoint, replace=True)
                    fresh = False
                ep = branch_episode(rollout, checkpoint=pair.checkpoint, seed=pair.seed, extra=extra)
                slot = redo.get((pair.pair_id, origin))
                index = writer.append(ep) if slot is None else writer.replace(slot, ep)  # replace drops old verdicts
                if origin == "real":
                    verdicts = station.verdicts(sub, pair.checkpoint, index, rollout_length(rollout))
                    if verdicts:
                        record_outcomes(root, verdicts)
                rec = branch_record(pair.pair_id, rollout)
                records.append(rec)
                with (root / TIMINGS_FILE).open("a") as fh:
                    fh.write(json.dumps(rec) + "\n")
                back_up(root, [TIMINGS_FILE])
                if on_branch is not None:
                    on_branch(pair, origin)
            if fresh:  # every branch was copied from another run (real_from): still keep the scene's start
                starts.add(start, checkpoint=pair.checkpoint, replace=True)
            bar.update(1)
    bar.close()
    return _summary(root, plan, records, time.monotonic() - t_start)


def rollout_length(rollout: Rollout) -> int:
    return len(rollout.observations)


def _summary(root: Path, plan: list[PairedSubtask], records: list[dict[str, Any]], seconds: float) -> dict[str, Any]:
    from pilworld.data.info import dataset_info

    per_origin: dict[str, list[float]] = {o: [r["seconds"] for r in records if r["origin"] == o] for o in ORIGINS}
    return {
        "out": str(root),
        "pairs_planned": len(plan),
        "branches_run": len(records),
        "seconds": round(seconds, 2),
        "seconds_per_subtask": {
            o: {"median": round(float(np.median(v)), 3), "mean": round(float(np.mean(v)), 3), "n": len(v)}
            for o, v in per_origin.items()
            if v
        },
        "dataset": dataset_info(root),
    }
