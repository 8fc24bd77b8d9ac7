"""The whole bench: the horizon runs beside the probes (in a process of their own), per model."""

from __future__ import annotations

import concurrent.futures
import multiprocessing as mp
import time
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from pilworld.bench.common import machine_info
from pilworld.bench.stability.horizon import horizon_sweep
from pilworld.bench.stability.models import resolve_models
from pilworld.bench.stability.prober import probe
from pilworld.bench.stability.settings import HORIZONS, PROBE_SEED0, QUICK_CHECKPOINTS, STABILITY_SEED0
from pilworld.bench.variants import PairedProtocol, evaluate_variants
from pilworld.types import ChunkSpec


def _probe_job(kwargs: dict[str, Any]) -> dict[str, Any]:
    """:func:`probe` in a spawned process (module level, so the pool can pickle it)."""
    return probe(**kwargs, progress=False)


def run_stability(
    *,
    rig: str | Path,
    quick: bool = False,
    out: str | Path = "bench_runs/stability",
    subtasks: int | None = None,
    starts: int | None = None,
    workers: int | None = None,
    models: Sequence[str] | None = None,
    progress: bool = True,
) -> dict[str, Any]:
    """The whole bench for ``models`` (default ``DEFAULT_MODELS``); see the module docstring."""
    from pilworld.bench.paired import failure_faithfulness
    from simrig.tasks import TASK_NAMES

    t0 = time.monotonic()
    variants = resolve_models(models)
    for v in variants:  # fail before the horizon runs, naming the missing weights
        v.check()
    rounds = max(HORIZONS)
    tasks = tuple(TASK_NAMES)
    proto = PairedProtocol(tasks, QUICK_CHECKPOINTS, subtasks or (1 if quick else 5), rounds, STABILITY_SEED0)
    horizon_protocol = {
        "tasks": list(tasks),
        "checkpoints": list(proto.checkpoints),
        "subtasks": proto.subtasks,
        "rounds": rounds,
        "seed0": proto.seed,
    }
    probe_args: dict[str, Any] = {
        "rig": str(rig),
        "tasks": tasks,
        "checkpoints": QUICK_CHECKPOINTS,
        "starts": starts or (1 if quick else 4),
        "models": variants,
        "seed0": PROBE_SEED0,
    }
    from pilworld.paired.imagined_branch import torch_threads

    # The probes run in a process of their own beside the horizon runs (one core each most of the time: the
    # paired runs are sequential), unless a single process was asked for.
    with concurrent.futures.ProcessPoolExecutor(1, mp_context=mp.get_context("spawn")) as pool:
        probing = None
        if workers != 1:
            if progress:
                print("probes: in a process of their own, beside the horizon runs", flush=True)
            probing = pool.submit(_probe_job, probe_args)
        with torch_threads(1):
            results = evaluate_variants(
                variants, proto, Path(out) / "horizon", rig=rig, workers=workers, progress=progress, single_step=False
            )
        probes = probing.result() if probing is not None else probe(**probe_args, progress=progress)
    per_model: dict[str, Any] = {}
    for v in variants:
        run = Path(results[v.name]["out"])
        horizon = horizon_sweep(run, rounds, ChunkSpec().frames)
        horizon["protocol"] = horizon_protocol
        p = probes["models"][v.name]
        per_model[v.name] = {
            "label": v.label,
            "horizon": horizon,
            "failure_faithfulness": failure_faithfulness(str(run)),
            **{k: p[k] for k in p if k != "label"},
        }
    return {
        "bench": "stability",
        "quick": quick,
        "models": per_model,
        "probe_protocol": probes["protocol"],
        "refused": probes["refused"],
        "machine": machine_info(),
        "wall_s": round(time.monotonic() - t0, 1),
    }
