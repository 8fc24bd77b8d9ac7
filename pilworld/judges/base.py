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
    """The simulated task of a stored episode (``extra.sim_task``), or "" for data from elsewhere."""
    return str(episode.extra.get("sim_task", ""))


def judge_dataset(
    root: str | Path,
    judges: Sequence[Judge],
    rig: RigConfig,
    *,
    episodes: Iterable[int] | None = None,
    progress: bool = False,
) -> list[Outcome]:
    """Run ``judges`` on the episodes of ``root`` (all by default) and record their verdicts."""
    store = EpisodeStore(root)
    indices = list(range(store.num_episodes)) if episodes is None else list(episodes)
    outcomes: list[Outcome] = []
    for i in tqdm(indices, desc="judging", unit="episode", disable=not progress):
        ep = store.load(i)
        ctx = JudgeContext(rig=rig, task=episode_task(ep))
        for j in judges:
            t0 = time.perf_counter()
            v = j.judge(ep, ctx)
            if v.success is None:
                continue  # a hallucination-only judge: its frame is merged by the caller, see metrics
            outcomes.append(
                Outcome(
                    episode_index=i,
                    judge_id=j.judge_id,
                    judge_kind=j.kind,
                    success=v.success,
                    num_frames=ep.length,
                    first_hallucination_frame=v.first_hallucination_frame,
                    judge_seconds=time.perf_counter() - t0,
                )
            )
    if outcomes:
        record_outcomes(root, outcomes, num_episodes=store.num_episodes)
    return outcomes


def unjudged_episodes(root: str | Path, judge_id: str) -> list[int]:
    """Episodes of ``root`` without a verdict of ``judge_id`` (what a resumed judging pass still has to do)."""
    have = {o.episode_index for o in read_outcomes(root) if o.judge_id == judge_id}
    return [i for i in range(EpisodeStore(root).num_episodes) if i not in have]
