"""Reuse the real branches of another paired run (``PairedConfig.real_from``).

The real branch of a pair does not depend on the world model: the same rig, task, checkpoint, layout
seed and chunk spec give the same rollout. Benchmarks that compare several world models on the same
pairs (``pilworld bench paired``) therefore run the real branches once and copy them — episode,
frames and every verdict already recorded for it (the simulator's checker, the image-only judge) —
into each model's run. Each run folder stays self-contained, so metrics, reports and annotation work
on it unchanged, and a copied episode says where it came from in ``extra.real_from``.
"""

from __future__ import annotations

import dataclasses
import json
from pathlib import Path
from typing import TYPE_CHECKING, Any

from pilworld.data.outcomes import Outcome, read_outcomes, record_outcomes
from pilworld.data.reader import EpisodeStore
from pilworld.data.writer import EpisodeWriter
from pilworld.paired.config import CONFIG_FILE, TASK_HASHES, settings_diff, stored_config

if TYPE_CHECKING:
    from pilworld.paired.config import PairedConfig

# Settings that decide the real branch; the world model, its adapter and sampling steps do not. (The task
# files must match too: compared by their hashes, task by task.)
REAL_BRANCH_KEYS = ("rig", "seed", "video_mode", "spec", "instruction", "appearance")


class RealBranchSource:
    """The real episodes of a finished (or partly finished) paired run, by pair id."""

    def __init__(self, root: str | Path, cfg: PairedConfig) -> None:
        self.root = Path(root)
        path = self.root / CONFIG_FILE
        if not path.is_file():
            raise FileNotFoundError(f"real_from: {self.root} holds no paired run ({CONFIG_FILE} missing)")
        have = stored_config(path)
        diff = settings_diff(have, json.loads(json.dumps(cfg.to_json())), REAL_BRANCH_KEYS)
        hashes = have.get(TASK_HASHES)
        if isinstance(hashes, dict):
            diff += [f"task {t.name}" for t in cfg.task_files if hashes.get(t.name, t.digest) != t.digest]
        if diff:
            raise ValueError(
                f"real_from: {self.root} was run with other settings ({', '.join(diff)}); its real branches "
                "are not this run's"
            )
        self.store = EpisodeStore(self.root)
        self.index: dict[str, int] = {}
        for i, row in enumerate(self.store.episodes):
            extra = json.loads(row.get("extra") or "{}")
            if str(row.get("origin")) == "real" and "pair" in extra:
                self.index[str(extra["pair"])] = i
        self.outcomes: dict[int, list[Outcome]] = {}
        for o in read_outcomes(self.root):
            self.outcomes.setdefault(o.episode_index, []).append(o)

    def has(self, pair_id: str) -> bool:
        return pair_id in self.index

    def copy(self, pair_id: str, writer: EpisodeWriter, out_root: Path, *, index: int | None = None) -> tuple[int, int]:
        """Append the pair's real episode to ``writer`` with its verdicts; returns (new index, frames).

        With ``index`` it rewrites that stored episode instead (a damaged branch a resume redoes)."""
        if pair_id not in self.index:
            raise KeyError(f"real_from: {self.root} has no real branch of pair {pair_id} (run it there first)")
        src = self.index[pair_id]
        ep = self.store.load(src)
        extra: dict[str, Any] = {**ep.extra, "real_from": str(self.root), "real_from_index": src}
        # Same spec (fps, views, video mode): the source's own mp4s are this episode's frames, copied as they are.
        files = None
        if self.store.spec == writer.spec:
            own = {v: self.store.own_video_file(src, v) for v in writer.spec.views}
            files = {v: p for v, p in own.items() if p is not None} or None
        copied = dataclasses.replace(ep, extra=extra)
        if index is None:
            index = writer.append(copied, video_files=files)
        else:
            index = writer.replace(index, copied, video_files=files)
        verdicts = [dataclasses.replace(o, episode_index=index) for o in self.outcomes.get(src, [])]
        if verdicts:
            record_outcomes(out_root, verdicts)
        return index, ep.length
