"""The lab of one run: the simulated robot, the policies, the world models per task, and the resumable caches."""

from __future__ import annotations

import dataclasses
import json
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

from tqdm import tqdm

from pilworld.bench.wm_ladder.model import load_ladder_model
from pilworld.bench.wm_ladder.real_store import load_rollout, save_rollout
from pilworld.bench.wm_ladder.settings import VERSION, LadderConfig, check_model_folder, digest, safe_pair_id
from pilworld.config.rig import RigConfig
from pilworld.data.episode import Episode
from pilworld.paired.runner import PairedSubtask
from pilworld.rollout import Rollout
from pilworld.types import Start
from pilworld.world_model.base import WorldModel


class RecordCache:
    """Per-pair records of one rung in ``<out>/<rung>.jsonl``, reused when their settings key matches."""

    def __init__(self, path: Path, key: str) -> None:
        self.path = path
        self.key = key
        self.records: dict[str, dict[str, Any]] = {}
        if path.is_file():
            for line in path.read_text().splitlines():
                try:
                    row = json.loads(line)
                except json.JSONDecodeError:
                    continue  # a line cut by a kill
                if row.get("key") == key:
                    self.records[row["pair"]] = row["record"]

    def get(self, pair: str) -> dict[str, Any] | None:
        return self.records.get(pair)

    def put(self, pair: str, record: dict[str, Any]) -> None:
        self.records[pair] = record
        self.path.parent.mkdir(parents=True, exist_ok=True)
        with self.path.open("a") as fh:
            fh.write(json.dumps({"key": self.key, "pair": pair, "record": record}) + "\n")


class Lab:
    """The simulated robot, the policies, the world models per task and the real-branch store of one run."""

    def __init__(self, cfg: LadderConfig) -> None:
        from pilworld.control_video.gamma import ControlVideo

        self.cfg = cfg
        self.spec = cfg.spec
        self.rig_cfg = RigConfig.load(cfg.rig)
        self.out = Path(cfg.out)
        self.model_path = cfg.model_path
        check_model_folder(self.model_path)
        self.gamma = ControlVideo.from_rig(self.rig_cfg, self.spec)
        spec_json = dataclasses.asdict(self.spec)
        self.real_key = digest({"v": VERSION, "rig": str(Path(cfg.rig).resolve()), "spec": spec_json})
        self.model_key = digest({"real": self.real_key, "model": str(self.model_path.resolve())})
        self._robot: Any = None
        self._policies: dict[str, Any] = {}
        self._models: dict[str, tuple[WorldModel, str | None, bool]] = {}
        self.real_runs = 0
        self.learned: Any = None  # the learned judge of rungs 2 and 3 (LearnedSuccessJudge), None = none
        self.judge_key = "none"
        if cfg.judge_path is not None:
            from pilworld.judges.learned.apply import judge_digest
            from pilworld.judges.learned.judge import LearnedSuccessJudge

            self.learned = LearnedSuccessJudge(cfg.judge_path)  # a bad folder fails before anything runs
            self.judge_key = judge_digest(self.learned.folder)

    # -- resources, made on first use

    @property
    def robot(self) -> Any:
        if self._robot is None:
            from simrig.robot import SimRobot

            self._robot = SimRobot(self.rig_cfg, self.cfg.tasks[0])
            self._robot.connect()
        return self._robot

    def close(self) -> None:
        if self._robot is not None:
            self._robot.disconnect()
            self._robot = None

    def policy(self, checkpoint: str) -> Any:
        if checkpoint not in self._policies:
            from pilworld.policies.registry import make_policy

            self._policies[checkpoint] = make_policy(checkpoint, self.rig_cfg, self.spec)
        return self._policies[checkpoint]

    def model(self, task: str) -> tuple[WorldModel, str | None, bool]:
        if task not in self._models:
            self._models[task] = load_ladder_model(self.model_path, self.rig_cfg, self.spec, task)
        return self._models[task]

    def start(self, pair: PairedSubtask) -> Start:
        sub = pair.subtask
        start: Start = self.robot.reset(
            seed=sub.seed, subtask=sub.index, task=sub.task, history=self.spec.history, stride=self.spec.stride
        )
        return start

    def run_branch(self, pair: PairedSubtask, wrap: Callable[[Any], Any] | None = None) -> tuple[Rollout, Any, bool]:
        """One real-branch run of ``pair`` (the env optionally wrapped): (rollout, env, checker success)."""
        from pilworld.envs import RobotEnv
        from pilworld.rollout import closed_loop

        start = self.start(pair)
        policy = self.policy(pair.checkpoint)
        policy.reset(seed=pair.seed)
        env: Any = RobotEnv(self.robot, self.spec, pace=False)
        if wrap is not None:
            env = wrap(env)
        rollout = closed_loop(policy, env, pair.subtask.instruction, self.spec.rounds, start=start)
        success = bool(self.robot.check_subtask(pair.subtask.index).success)
        return rollout, env, success

    def real(self, pair: PairedSubtask) -> tuple[Rollout, bool]:
        """The plain real branch of ``pair`` and its checker verdict, run once and kept on disk."""
        path = self.out / "real" / self.real_key / f"{safe_pair_id(pair.pair_id)}.npz"
        if path.is_file():
            try:
                rollout, info = load_rollout(path)
                return rollout, bool(info["success"])
            except (OSError, ValueError, KeyError):
                path.unlink(missing_ok=True)  # a damaged file: run it again
        rollout, _, success = self.run_branch(pair)
        save_rollout(path, rollout, {"success": success, "pair": pair.pair_id})
        self.real_runs += 1
        return rollout, success

    def episode(self, pair: PairedSubtask, rollout: Rollout) -> Episode:
        from pilworld.collection.tasks import task_extra
        from pilworld.paired.episodes import rollout_episode
        from simrig.tasks import load_task

        return rollout_episode(
            rollout,
            checkpoint=pair.checkpoint,
            seed=pair.seed,
            extra={"pair": pair.pair_id, **task_extra(load_task(pair.subtask.task))},
        )

    def context(self, task: str) -> Any:
        from pilworld.judges.base import JudgeContext

        return JudgeContext(rig=self.rig_cfg, task=task)


def _pairs_of(cache: RecordCache, plan: Sequence[PairedSubtask]) -> list[tuple[PairedSubtask, dict[str, Any]]]:
    out = []
    for p in plan:
        rec = cache.get(p.pair_id)
        if rec is not None:
            out.append((p, rec))
    return out


def each_pair(
    lab: Lab,
    rung: str,
    key: dict[str, Any],
    plan: Sequence[PairedSubtask],
    record: Callable[[PairedSubtask, int], dict[str, Any]],
    progress: bool,
) -> list[tuple[PairedSubtask, dict[str, Any]]]:
    """Every pair's record of ``rung`` (cached ones reused), with a progress bar."""
    cache = RecordCache(lab.out / f"{rung}.jsonl", digest({"v": VERSION, "rung": rung, **key}))
    todo = [(i, p) for i, p in enumerate(plan) if cache.get(p.pair_id) is None]
    bar = tqdm(
        total=len(plan), initial=len(plan) - len(todo), desc=f"wm-ladder {rung}", unit="pair", disable=not progress
    )
    for i, p in todo:
        cache.put(p.pair_id, record(p, i))
        bar.update(1)
    bar.close()
    return _pairs_of(cache, plan)
