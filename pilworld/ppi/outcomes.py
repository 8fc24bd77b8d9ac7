"""The outcomes PPI combines, read from run folders: real y and imagined f per pair, f alone per imagined-only branch.

* **y, the real outcome** (the "gold label"): the real branch's verdict by the most trustworthy judge
  present — the simulator's privileged checker (``sim_checker``), else the operator at the rig
  (``operator``), else the mean of people's labels (kind ``human``), else the proxy judge itself on the
  real frames. ``gold`` names one judge id instead.
* **f, the imagined outcome** (the "prediction"): the imagined branch's verdict by the ``proxy`` judge.
  By default (:func:`default_proxy`) the judge the run's selection names (:mod:`pilworld.data.judge_selection`),
  else the learned judge where the run has its verdicts (``learned``, ``pilworld judge apply``), else the
  paper tasks' hand-written reference (``vision``) on runs judged by nothing else. It must be the same judge
  in the paired run and in the imagined-only runs (``pilworld imagine --judge`` records ``learned``): a
  prediction is only as comparable as the rule that makes it.

Imagined-only branches whose pair id is also a pair of the paired run are left out of the unlabelled
set: they are the same subtask, already counted with its real outcome.
"""

from __future__ import annotations

import json
from collections import defaultdict
from dataclasses import dataclass, field
from pathlib import Path

from pilworld.data.outcomes import Outcome, judges_with_verdicts, read_outcomes
from pilworld.data.pairs import load_pairs
from pilworld.data.reader import EpisodeStore

LEARNED_PROXY = "learned"  # pilworld.judges.learned.apply.LEARNED_ID (not imported: ppi stays below the judges)
REFERENCE_PROXY = "vision"  # the paper tasks' hand-written judge, for runs no learned judge has judged
GOLD_ORDER = ("sim_checker", "operator")  # then people's labels (kind human), then the proxy judge on real frames
ATTACHED_FILE = "imagined_runs.json"  # RUN/imagined_runs.json: the imagined-only runs attached to a paired run


@dataclass
class CheckpointOutcomes:
    """One checkpoint's (or task × checkpoint's) outcomes: labelled pairs and unlabelled predictions."""

    y: list[float] = field(default_factory=list)
    f: list[float] = field(default_factory=list)
    unlabeled: list[float] = field(default_factory=list)
    gold_judges: set[str] = field(default_factory=set)
    skipped_pairs: int = 0  # pairs without a gold or a proxy verdict


@dataclass
class RunOutcomes:
    by_checkpoint: dict[str, CheckpointOutcomes]
    by_setting: dict[tuple[str, str], CheckpointOutcomes]  # (task, checkpoint)
    proxy: str
    imagined_runs: list[str]
    overlapping: int  # imagined-only branches left out because the paired run has the same pair


def _gold(verdicts: list[Outcome], gold: str | None, proxy: str) -> tuple[float, str] | None:
    by_id = {o.judge_id: o for o in verdicts}
    if gold is not None:
        return (float(by_id[gold].success), gold) if gold in by_id else None
    for judge in GOLD_ORDER:
        if judge in by_id:
            return float(by_id[judge].success), judge
    humans = [o for o in verdicts if o.judge_kind == "human"]
    if humans:
        return sum(float(o.success) for o in humans) / len(humans), "human"
    if proxy in by_id:
        return float(by_id[proxy].success), proxy
    return None


def attached_runs(root: Path) -> list[str]:
    """The imagined-only runs attached to the paired run at ``root`` (``pilworld report --imagined``)."""
    path = root / ATTACHED_FILE
    if not path.is_file():
        return []
    runs = json.loads(path.read_text()).get("imagined_runs", [])
    return [str(r) for r in runs]


def attach_runs(root: Path, runs: list[str], proxy: str | None = None) -> list[str]:
    """Remember ``runs`` (besides those attached before) so later metrics include them, and ``proxy`` as the
    proxy judge when given (kept otherwise); returns every attached run."""
    from pilworld.io.atomic import write_json

    for r in runs:
        if not (Path(r) / "imagine_config.json").is_file():
            raise FileNotFoundError(f"--imagined: {r} holds no imagined-only run (imagine_config.json missing)")
    path = root / ATTACHED_FILE
    before = json.loads(path.read_text()) if path.is_file() else {}
    every = list(dict.fromkeys([*attached_runs(root), *[str(Path(r).resolve()) for r in runs]]))
    proxy = proxy or before.get("proxy_judge")
    write_json(path, {"imagined_runs": every} | ({"proxy_judge": proxy} if proxy else {}))
    return every


def default_proxy(root: str | Path) -> str:
    """The proxy judge of the run at ``root``: the one ``pilworld report --proxy-judge`` recorded, else the one its
    judge selection names, else ``learned`` where it has that judge's verdicts, else ``vision``."""
    from pilworld.data.judge_selection import read_selection

    attached = Path(root) / ATTACHED_FILE
    recorded = json.loads(attached.read_text()).get("proxy_judge") if attached.is_file() else None
    if recorded:
        return str(recorded)  # pilworld report --proxy-judge
    chosen = read_selection(root).judges
    if chosen is not None and len(chosen) == 1:
        return chosen[0]
    if LEARNED_PROXY in judges_with_verdicts(root):
        return LEARNED_PROXY
    return REFERENCE_PROXY


def read_run_outcomes(
    root: str | Path, imagined: list[str] | None = None, *, gold: str | None = None, proxy: str | None = None
) -> RunOutcomes:
    """y and f of every pair of the paired run at ``root``, and f of every branch of the imagined-only runs
    (default: those attached to it); ``proxy`` None: :func:`default_proxy`."""
    root = Path(root)
    proxy = default_proxy(root) if proxy is None else proxy
    paired = load_pairs(root)
    by_ckpt: dict[str, CheckpointOutcomes] = defaultdict(CheckpointOutcomes)
    by_setting: dict[tuple[str, str], CheckpointOutcomes] = defaultdict(CheckpointOutcomes)
    labelled: set[str] = set()
    for pair in paired.pairs:
        labelled.add(pair.pair_id)
        y = _gold(paired.outcomes(pair.real), gold, proxy)
        f = {o.judge_id: o for o in paired.outcomes(pair.imagined)}.get(proxy)
        for group in (by_ckpt[pair.checkpoint], by_setting[pair.setting]):
            if y is None or f is None:
                group.skipped_pairs += 1
                continue
            group.y.append(y[0])
            group.f.append(float(f.success))
            group.gold_judges.add(y[1])
    runs = attached_runs(root) if imagined is None else [str(r) for r in imagined]
    overlapping = 0
    for run in runs:
        store = EpisodeStore(run)
        verdicts = {o.episode_index: o for o in read_outcomes(Path(run)) if o.judge_id == proxy}
        for i, row in enumerate(store.episodes):
            extra = json.loads(row.get("extra") or "{}")
            pair_id = str(extra.get("pair", ""))
            if str(row.get("origin")) != "imagined" or i not in verdicts:
                continue
            if pair_id in labelled:
                overlapping += 1
                continue
            task = str(extra.get("task") or extra.get("sim_task") or row.get("task") or "")
            ckpt = str(row.get("checkpoint") or "")
            value = float(verdicts[i].success)
            by_ckpt[ckpt].unlabeled.append(value)
            by_setting[(task, ckpt)].unlabeled.append(value)
    return RunOutcomes(dict(by_ckpt), dict(by_setting), proxy, runs, overlapping)
