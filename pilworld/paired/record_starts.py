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
from pilworld.paired.runner import PairedConfig, check_station_tasks, plan_subtasks
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
    instruction: str = "",
    appearance: str = "flat",
) -> dict[str, Any]:
    """Record ``count`` starts per task (subtasks 0, 1, … of layout ``seed``, then ``seed + 1``, …).

    ``task`` as a paired run takes it (names, task files, comma-separated, or all); ``instruction`` replaces
    each task's own in the recorded starts. Everything is checked before the folder is created."""
    from pilworld.collection.collect import dataset_spec
    from pilworld.config.rig import RigConfig
    from pilworld.io.run_folder import STARTS, check_out_folder

    check_out_folder(out, STARTS)  # a folder another command made is refused before anything else
    spec = spec or ChunkSpec()
    # The paired run's own validation of rig, tasks, instruction and count (no checkpoint runs here).
    cfg = PairedConfig(
        rig=rig,
        task=task,
        checkpoints=["-"],
        subtasks=count,
        out=str(out),
        seed=seed,
        spec=spec,
        instruction=instruction,
        appearance=appearance,
    )
    tasks = cfg.task_files
    rig_cfg = RigConfig.load(rig)
    check_station_tasks(rig_cfg, tasks, operator)
    store_spec = dataset_spec(rig, "lossless", spec)
    plan = []
    for t in tasks:
        plan += [p.subtask for p in plan_subtasks(t.name, count, seed, ["-"], t.num_subtasks, cfg.instruction_for(t))]
    written = 0
    with (
        open_station(rig, {t.name: t for t in tasks}, operator, appearance=appearance) as station,
        StartsWriter(
            out, store_spec, station.robot.spec, spec, rig=rig, task_sha256={t.name: t.digest for t in tasks}
        ) as writer,
    ):
        todo = [s for s in plan if (start_id(s), "") not in writer.stored()]
        bar = tqdm(total=len(plan), initial=len(plan) - len(todo), desc="starts", unit="start", disable=not progress)
        for sub in todo:
            written += writer.add(station.start(sub, "", spec))
            bar.update(1)
        bar.close()
    return {"out": str(out), "starts_planned": len(plan), "starts_recorded": written}
