"""The judge contract: an episode in, a verdict out (paper §4 "Evaluation protocol", DESIGN.md "Contracts").

Every judge — the simulator's privileged checker, the image-only success judge, the automatic
hallucination detector, a person in the annotation app — answers the same two questions about one
stored episode: did it achieve its subtask, and from which frame on (if any) does it show a
hallucination. Verdicts are recorded in the dataset's outcomes table (``meta/outcomes.parquet``), one
row per (episode, judge); the metrics read only that table.

A judge sees what is stored (frames, states, actions, instruction, ``extra.sim_task``) plus the rig
config for geometry (the head camera and the kinematics). Image-only judges must not read privileged
simulator state.
"""

from __future__ import annotations

import time
from collections.abc import Iterable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Protocol, runtime_checkable

from tqdm import tqdm

from pilworld.config.rig import RigConfig
from pilworld.data.episode import Episode
from pilworld.data.outcomes import JudgeKind, Outcome, read_outcomes, record_outcomes
from pilworld.data.reader import EpisodeStore


@dataclass(frozen=True)
class Verdict:
    """A judge's answer for one episode.

    ``success`` is ``None`` for a judge that only looks for hallucinations (it then records no success
    verdict of its own); ``first_hallucination_frame`` is ``None`` when none was seen.
    """

    success: bool | None
    first_hallucination_frame: int | None = None
    reason: str = ""

    def __post_init__(self) -> None:
        f = self.first_hallucination_frame
        if f is not None and (isinstance(f, bool) or not isinstance(f, int) or f < 0):
            raise ValueError(f"first_hallucination_frame: expected None or an integer >= 0, got {f!r}")


@dataclass(frozen=True)
class JudgeContext:
    """What a judge may know besides the episode: the rig's geometry and the simulated task's name."""

    rig: RigConfig
    task: str  # the simulated task (``extra.sim_task``), e.g. "sort_cubes"; "" when unknown


@runtime_checkable
class Judge(Protocol):
    """``judge_id`` names the judge in the outcomes table; ``kind`` is sim_state | vision | human."""

    @property
    def judge_id(self) -> str: ...

    @property
    def kind(self) -> JudgeKind: ...

    def judge(self, episode: Episode, context: JudgeContext) -> Verdict: ...


def episode_task(episode: Episode) -> str:
    """The task of a stored episode (``extra.task``; older data: ``extra.sim_task``), or "" for data from elsewhere."""
    return str(episode.extra.get("task") or episode.extra.get("sim_task") or "")


def judge_episode(store: EpisodeStore, index: int, judges: Sequence[Judge], rig: RigConfig) -> list[Outcome]:
    """The verdicts of ``judges`` on episode ``index`` of ``store``, as outcome rows."""
    ep = store.load(index)
    ctx = JudgeContext(rig=rig, task=episode_task(ep))
    outcomes: list[Outcome] = []
    for j in judges:
        t0 = time.perf_counter()
        v = j.judge(ep, ctx)
        if v.success is None:
            continue  # a hallucination-only judge: its frame is merged by the caller, see metrics
        outcomes.append(
            Outcome(
                episode_index=index,
                judge_id=j.judge_id,
                judge_kind=j.kind,
                success=v.success,
                num_frames=ep.length,
                first_hallucination_frame=v.first_hallucination_frame,
                judge_seconds=time.perf_counter() - t0,
            )
        )
    return outcomes


_STORES: dict[str, EpisodeStore] = {}  # per worker process: opening a store reads its metadata once


def worker_store(root: str) -> EpisodeStore:
    """The episode store at ``root``, opened once per process (for judging jobs run in worker processes)."""
    if root not in _STORES:
        _STORES[root] = EpisodeStore(root)
    return _STORES[root]


def _judge_job(job: tuple[str, Sequence[Judge], RigConfig, int]) -> list[Outcome]:
    root, judges, rig, index = job
    return judge_episode(worker_store(root), index, judges, rig)


def judge_dataset(
    root: str | Path,
    judges: Sequence[Judge],
    rig: RigConfig,
    *,
    episodes: Iterable[int] | None = None,
    progress: bool = False,
    workers: int | None = 1,
    flush_every: int = 16,
) -> list[Outcome]:
    """Run ``judges`` on the episodes of ``root`` (all by default) and record their verdicts.

    ``workers`` processes judge episodes in parallel (``None``: one per CPU; judging is pure CPU, an
    image-only judge takes ~0.7 s per 76-frame episode). Verdicts are written every ``flush_every`` episodes,
    so an interrupted pass keeps what it finished and :func:`unjudged_episodes` resumes it.
    """
    from pilworld.collection.workers import process_map, worker_count

    if flush_every < 1:
        raise ValueError(f"flush_every: expected at least 1, got {flush_every}")
    store = EpisodeStore(root)
    indices = list(range(store.num_episodes)) if episodes is None else list(episodes)
    bad = sorted(i for i in indices if not 0 <= i < store.num_episodes)
    if bad:
        raise ValueError(f"episodes: {bad[:10]} not in {root} (it has {store.num_episodes} episodes)")
    n_workers = worker_count(workers, len(indices))
    outcomes: list[Outcome] = []
    pending: list[Outcome] = []
    done = 0
    if n_workers <= 1:
        results: Iterable[list[Outcome]] = (judge_episode(store, i, judges, rig) for i in indices)
    else:
        jobs = [(str(root), judges, rig, i) for i in indices]
        results = process_map(_judge_job, jobs, n_workers, ordered=False)
    try:
        with tqdm(total=len(indices), desc="judging", unit="episode", disable=not progress) as bar:
            for rows in results:
                outcomes.extend(rows)
                pending.extend(rows)
                done += 1
                bar.update(1)
                if pending and done % flush_every == 0:
                    record_outcomes(root, pending, num_episodes=store.num_episodes)
                    pending = []
    finally:  # a judge that raised, or Ctrl-C: what was finished is kept
        if pending:
            record_outcomes(root, pending, num_episodes=store.num_episodes)
    return sorted(outcomes, key=lambda o: (o.episode_index, o.judge_id))


def unjudged_episodes(root: str | Path, judge_id: str) -> list[int]:
    """Episodes of ``root`` without a verdict of ``judge_id`` (what a resumed judging pass still has to do)."""
    have = {o.episode_index for o in read_outcomes(root) if o.judge_id == judge_id}
    return [i for i in range(EpisodeStore(root).num_episodes) if i not in have]
