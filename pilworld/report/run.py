"""What a report reads from a paired run folder: pairs of episodes, verdicts, settings, metrics.

A paired run folder (``docs/paired.md``) holds one dataset in the episode store with an imagined and a
real episode per pair (``extra.pair`` names the pair), the outcomes table, ``paired_config.json``,
``paired_timings.jsonl`` and, once the metrics are computed, ``metrics.json``. Everything but the dataset
is optional here: a report of a run in progress, or of one not yet judged or scored, shows what there is.
"""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from pilworld.data.outcomes import Outcome, read_outcomes
from pilworld.data.reader import EpisodeStore

CONFIG_FILE = "paired_config.json"  # the names pilworld.paired.runner writes
TIMINGS_FILE = "paired_timings.jsonl"
METRICS_FILE = "metrics.json"
BRANCHES = ("real", "imagined")  # column order in the report


@dataclass
class PairInfo:
    """One pair: the episode index of each stored branch and their labels."""

    pair_id: str
    episodes: dict[str, int] = field(default_factory=dict)  # origin → episode index
    task: str = ""  # the task's name (extra.task; older runs extra.sim_task), else the instruction
    instruction: str = ""
    checkpoint: str = ""
    seed: int = 0
    subtask_index: int = 0
    length: dict[str, int] = field(default_factory=dict)  # origin → frames
    seconds: dict[str, float] = field(default_factory=dict)  # origin → branch wall time (paired_timings.jsonl)

    @property
    def missing(self) -> list[str]:
        return [b for b in BRANCHES if b not in self.episodes]


@dataclass
class RunData:
    """The parts of a run folder a report shows (the frames are loaded pair by pair, later)."""

    root: Path
    store: EpisodeStore
    pairs: list[PairInfo]
    outcomes: dict[int, list[Outcome]]  # episode index → verdicts, by judge id
    config: dict[str, Any] | None  # paired_config.json, None when absent
    metrics: dict[str, Any] | None  # metrics.json, None when absent
    metrics_error: str = ""  # why metrics.json could not be read (it exists but is not a JSON object)


def _read_json_object(path: Path) -> tuple[dict[str, Any] | None, str]:
    if not path.is_file():
        return None, ""
    try:
        value = json.loads(path.read_text(encoding="utf-8"))
    except (json.JSONDecodeError, UnicodeDecodeError) as err:
        return None, f"{path.name} is not valid JSON ({err})"
    if not isinstance(value, dict):
        return None, f"{path.name} holds a {type(value).__name__}, expected a JSON object"
    return value, ""


def _timings(root: Path) -> dict[tuple[str, str], float]:
    """(pair id, origin) → seconds of the last record (a resumed run appends; the last one stored counts)."""
    path = root / TIMINGS_FILE
    out: dict[tuple[str, str], float] = {}
    if not path.is_file():
        return out
    for line in path.read_text(encoding="utf-8").splitlines():
        try:
            rec = json.loads(line)
            out[(str(rec["pair"]), str(rec["origin"]))] = float(rec["seconds"])
        except (json.JSONDecodeError, KeyError, TypeError, ValueError):
            continue  # a line cut short by a killed run
    return out


def read_run(run_dir: str | Path) -> RunData:
    """Read a paired run folder; raises ``ValueError`` naming the folder if it holds no paired episodes."""
    root = Path(run_dir)
    if not root.is_dir():
        raise FileNotFoundError(f"RUN_DIR: {root} is not a folder")
    store = EpisodeStore(root)  # DatasetError (a ValueError) when there is no dataset
    timings = _timings(root)
    pairs: dict[str, PairInfo] = {}
    for i, row in enumerate(store.episodes):
        extra = json.loads(row.get("extra") or "{}")
        if "pair" not in extra:
            continue
        origin = str(row.get("origin") or "")
        if origin not in BRANCHES:
            continue
        pid = str(extra["pair"])
        info = pairs.setdefault(pid, PairInfo(pid))
        info.episodes[origin] = i
        info.length[origin] = int(row["length"])
        if (pid, origin) in timings:
            info.seconds[origin] = timings[(pid, origin)]
    if not pairs:
        raise ValueError(f"RUN_DIR: {root} holds no paired episodes (no episode has extra.pair); is it a paired run?")
    for info in pairs.values():
        index = min(info.episodes.values())
        labels = store.labels(index, store.frame_table(index))
        info.instruction = str(labels["task"])
        extra = labels["extra"]
        info.task = str(extra.get("task") or extra.get("sim_task") or info.pair_id.split("/")[0] or info.instruction)
        info.checkpoint = str(labels["checkpoint"])
        info.seed = int(labels["seed"])
        info.subtask_index = int(labels["subtask_index"])
    outcomes: dict[int, list[Outcome]] = {}
    for o in read_outcomes(root):
        outcomes.setdefault(o.episode_index, []).append(o)
    config, _ = _read_json_object(root / CONFIG_FILE)
    metrics, metrics_error = _read_json_object(root / METRICS_FILE)
    ordered = sorted(pairs.values(), key=lambda p: min(p.episodes.values()))
    return RunData(root, store, ordered, outcomes, config, metrics, metrics_error)
