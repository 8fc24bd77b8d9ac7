"""A learned judge applied to a run: a verdict on every episode it is sure of, the rest queued for people.

``pilworld judge apply JUDGE RUN_DIR`` (docs/judges.md, "On a real rig") judges both branches of every
pair with one judge folder and records its verdicts as judge ``learned`` in the run's outcomes, where
the metrics read them like any judge's; each row also carries the task-free hallucination detector's first
frame (:class:`LearnedVisionJudge`), so SR and HFR both come from it. Where it abstains it records
nothing; those episodes are listed in ``RUN_DIR/judges/learned.json`` with the judge's name, digest and
validation figures, and ``pilworld annotate serve RUN_DIR --abstained`` queues exactly them for people.

Applying is resumable (a pass stopped half-way keeps what it recorded and judges the rest), and
applying *another* judge folder to the same run first withdraws the previous judge's verdicts, so the
``learned`` rows of a run always come from the one judge its record names.
"""

from __future__ import annotations

import hashlib
import json
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from pilworld.config.rig import RigConfig
from pilworld.data.episode import Episode
from pilworld.data.judge_selection import write_selection
from pilworld.data.outcomes import JudgeKind, read_outcomes, replace_judge_outcomes
from pilworld.data.reader import EpisodeStore
from pilworld.io.atomic import write_json
from pilworld.judges.base import JudgeContext, Verdict, judge_dataset
from pilworld.judges.hallucination import HallucinationDetector
from pilworld.judges.learned.folder import WEIGHTS_FILE, JudgeFolder
from pilworld.judges.learned.judge import LearnedSuccessJudge

LEARNED_ID = "learned"  # the judge_id of an applied learned judge's verdicts
RECORD = Path("judges") / f"{LEARNED_ID}.json"  # in the run folder: which judge, and what it left to people
RECORD_FORMAT = "pilworld-applied-judge/1"


class LearnedVisionJudge:
    """Judge ``learned``: the learned success verdict (None where it abstains) and the task-free detector's
    first hallucination frame in one verdict, so both land in one outcomes row (like the reference judge's)."""

    def __init__(self, success: LearnedSuccessJudge, hallucination: HallucinationDetector | None = None) -> None:
        self.success = success
        self.hallucination = hallucination or HallucinationDetector()

    @property
    def judge_id(self) -> str:
        return LEARNED_ID

    @property
    def kind(self) -> JudgeKind:
        return "vision"

    def judge(self, episode: Episode, context: JudgeContext) -> Verdict:
        s = self.success.judge(episode, context)
        if s.success is None:  # abstained: nothing is recorded, the episode goes to people whole
            return s
        h = self.hallucination.judge(episode, context)
        return Verdict(
            success=s.success,
            first_hallucination_frame=h.first_hallucination_frame,
            reason=f"success: {s.reason}; hallucination: {h.reason}",
        )


@dataclass(frozen=True)
class Applied:
    episodes: int
    judged: int  # episodes with a verdict of this judge (this pass and earlier ones)
    abstained: list[int]  # episodes it left to people
    withdrawn: int  # verdicts of a previous judge folder removed first
    record: Path


def judge_digest(folder: JudgeFolder) -> str:
    """The judge's identity: the SHA-256 of its weights file (the same training gives the same digest)."""
    h = hashlib.sha256()
    with (folder.path / WEIGHTS_FILE).open("rb") as f:
        for block in iter(lambda: f.read(1 << 20), b""):
            h.update(block)
    return h.hexdigest()


def read_record(run_dir: str | Path) -> dict[str, Any] | None:
    """The run's applied-judge record, or None when no learned judge was applied to it."""
    path = Path(run_dir) / RECORD
    if not path.is_file():
        return None
    try:
        data = json.loads(path.read_text())
    except (json.JSONDecodeError, UnicodeDecodeError) as err:
        raise ValueError(f"{path}: damaged, not JSON ({err}); apply the judge again to rewrite it") from None
    if not isinstance(data, dict) or data.get("format") != RECORD_FORMAT:
        raise ValueError(f"{path}: not a {RECORD_FORMAT!r} record; apply the judge again to rewrite it")
    return data


def apply_judge(
    judge: LearnedSuccessJudge,
    run_dir: str | Path,
    rig: RigConfig,
    *,
    workers: int | None = 1,
    progress: bool = False,
    select_as: str | None = None,
) -> Applied:
    """Judge every episode of ``run_dir`` with ``judge`` (resuming a pass of the same judge) and write the record.

    ``select_as``: also make ``learned`` the run's selected judge (:mod:`pilworld.data.judge_selection`), recording
    this as who set it; None leaves the selection alone."""
    root = Path(run_dir)
    store = EpisodeStore(root)
    if store.num_episodes == 0:
        raise ValueError(f"RUN_DIR: {root} holds no episodes to judge")
    folder = judge.folder
    digest = judge_digest(folder)
    previous = read_record(root)
    withdrawn = 0
    if previous is None or previous.get("sha256") != digest:
        # another judge's verdicts (or rows of unknown origin) must not mix with this one's
        withdrawn = replace_judge_outcomes(root, {LEARNED_ID}, [])
    record: dict[str, Any] = {
        "format": RECORD_FORMAT,
        "judge_id": LEARNED_ID,
        "name": folder.name,
        "folder": str(folder.path.resolve()),
        "sha256": digest,
        "threshold": folder.threshold,
        "validation": {k: folder.validation.get(k) for k in ("episodes", "accuracy_answered", "abstain_share")},
        "trained_on": {k: folder.data.get(k) for k in ("labels", "episodes", "sha256")},
        "episodes": store.num_episodes,
        "complete": False,  # written before judging: a stopped pass resumes with the same judge
        "judged": None,
        "abstained": None,
    }
    write_json(root / RECORD, record)
    have = {o.episode_index for o in read_outcomes(root) if o.judge_id == LEARNED_ID}
    todo = [i for i in range(store.num_episodes) if i not in have]  # abstentions are judged again: cheap, the same
    judge_dataset(root, [LearnedVisionJudge(judge)], rig, episodes=todo, progress=progress, workers=workers)
    have = {o.episode_index for o in read_outcomes(root) if o.judge_id == LEARNED_ID}
    abstained = [i for i in range(store.num_episodes) if i not in have]
    write_json(root / RECORD, record | {"complete": True, "judged": len(have), "abstained": abstained})
    if select_as is not None:
        write_selection(root, [LEARNED_ID], select_as)
    return Applied(store.num_episodes, len(have), abstained, withdrawn, root / RECORD)
