"""``pilworld paired record-starts``: subtask starts without running any policy — the cheap part of a trial.

On the simulated rig each start is a seeded layout (``SimRobot.reset``); on a hardware rig the operator
lays out each scene, the arms move to the start pose and the rig records the start observation and its
H_h history frames while they hold still. The starts go to a starts folder (:mod:`pilworld.starts.store`)
that ``pilworld imagine --starts`` runs imagined-only branches from. Resumable: a rerun skips stored starts.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

from tqdm import tqdm

from pilworld.paired.operator import Operator
from pilworld.paired.runner import PairedConfig, plan_subtasks
from pilworld.paired.stations import open_station
from pilworld.starts.store import StartsWriter, start_id
from pilworld.types import ChunkSpec


def record_starts(
    rig: str,
    task: str,
    count: int,
    out: str | Path,
    *,
    seed: int = 0,
    spec: ChunkSpec | None = None,
    operator: Operator | None = None,
    progress: bool = True,
) -> dict[str, Any]:
    """Record ``count`` starts per task (subtasks 0, 1, … of layout ``seed``, then ``seed + 1``, …)."""
    from pilworld.collection.collect import dataset_spec
    from simrig.tasks import make_task

    spec = spec or ChunkSpec()
    # The paired run's own validation of rig, task names and count (no checkpoint runs here).
    cfg = PairedConfig(rig=rig, task=task, checkpoints=["-"], subtasks=count, out=str(out), seed=seed, spec=spec)
    plan = []
    for t in cfg.tasks:
        info = make_task(t)
        plan += [p.subtask for p in plan_subtasks(t, count, seed, ["-"], info.num_subtasks, info.instruction)]
    written = 0
    with (
        open_station(rig, cfg.tasks[0], operator) as station,
        StartsWriter(out, dataset_spec(rig, "lossless", spec), station.robot.spec, spec, rig=rig) as writer,
    ):
        todo = [s for s in plan if (start_id(s), "") not in writer.stored()]
        bar = tqdm(total=len(plan), initial=len(plan) - len(todo), desc="starts", unit="start", disable=not progress)
        for sub in todo:
            written += writer.add(station.start(sub, "", spec))
            bar.update(1)
        bar.close()
    return {"out": str(out), "starts_planned": len(plan), "starts_recorded": written}
