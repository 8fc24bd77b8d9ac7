"""``pilworld bench chunk-latency``: one imagined round's wall time for several world models, in one run.

A round of the imagined branch is what a user waits for: the control video of the chunk (Γ, plus
whatever else the model computes from geometry — world model v2's Γ⁺ layers), the prediction of K
frames of every view, and the state. This bench times exactly that, ``ImaginedEnv.step(chunk)`` at
batch 1 with each model's default steps, from one simulated start and one scripted chunk. Models are
timed round-robin (one call of each in turn), so a machine that slows down mid-run slows all of them
alike, and the ratios to the first model are the figures to compare across machines (which differ
by up to 2× in absolute speed).
"""

from __future__ import annotations

import argparse
import platform
import time
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import NDArray

from pilworld.bench.flags import add_json, add_rig
from pilworld.bench.output import emit
from pilworld.config.rig import RigConfig
from pilworld.types import ChunkSpec, RobotSpec, Start
from pilworld.world_model.base import RigBound

if TYPE_CHECKING:
    from pilworld.envs import ImaginedEnv
    from pilworld.world_model.base import WorldModel

START_SEED = 8_500_000  # a layout no training or other bench uses


def parse_models(text: str) -> dict[str, str]:
    """``"v1=PATH,v2=PATH"`` (or bare paths, named by their folder) → name → folder."""
    out: dict[str, str] = {}
    for item in (t.strip() for t in text.split(",")):
        if not item:
            continue
        name, _, path = item.partition("=") if "=" in item else (Path(item).name, "", item)
        if not (Path(path) / "config.json").is_file():
            raise ValueError(f"--models: {path!r} ({name}) is not a world-model folder (no config.json)")
        if name in out:
            raise ValueError(f"--models: the name {name!r} is listed twice")
        out[name] = path
    if not out:
        raise ValueError("--models: expected at least one NAME=PATH")
    return out


@dataclass(frozen=True)
class RoundSetup:
    """One imagined round's inputs: a simulated start, the scripted policy's chunk from it, the rig."""

    start: Start
    chunk: NDArray[np.float32]  # the policy's chunk, as ImaginedEnv.step takes it
    rig: RigConfig
    spec: ChunkSpec
    robot_spec: RobotSpec


def round_setup(rig: str | Path, task: str = "sort_cubes") -> RoundSetup:
    """The start (layout :data:`START_SEED`, subtask 0 of ``task``) and the best scripted checkpoint's chunk."""
    from pilworld.policies.registry import make_policy
    from simrig.robot import SimRobot

    spec = ChunkSpec()
    rig_cfg = RigConfig.load(rig)
    robot = SimRobot(rig, task)
    robot.connect()
    try:
        start = robot.reset(seed=START_SEED, subtask=0, task=task, history=spec.history, stride=spec.stride)
        spec_robot = robot.spec
    finally:
        robot.disconnect()
    policy = make_policy("scripted_step_30k", rig_cfg, spec)
    policy.reset(seed=START_SEED)
    chunk = policy.infer(start.observation, start.subtask.instruction)
    return RoundSetup(start, chunk, rig_cfg, spec, spec_robot)


def imagined_env(model: WorldModel, setup: RoundSetup, *, steps: int | None = None) -> ImaginedEnv:
    """``model``'s imagined branch as the paired runner builds it (v2 bound to the rig's geometry)."""
    from hw_drivers.safety import SafetyFilter
    from pilworld.control_video.gamma import ControlVideo
    from pilworld.envs import ImaginedEnv

    if isinstance(model, RigBound):
        model.bind_rig(setup.rig)
    gamma = ControlVideo.from_rig(setup.rig, setup.spec)
    return ImaginedEnv(model, gamma, setup.spec, steps=steps, safety=SafetyFilter(setup.robot_spec))


def time_rounds(
    envs: Mapping[str, ImaginedEnv], setup: RoundSetup, *, repeats: int, warmup: int = 2
) -> dict[str, list[float]]:
    """Milliseconds of ``repeats`` rounds (``env.step(chunk)`` from the reset start) per env, after ``warmup``
    untimed ones; round-robin, one call of each env in turn, so a machine that slows down slows all alike."""
    if repeats < 1:
        raise ValueError(f"repeats: expected at least 1, got {repeats}")
    times: dict[str, list[float]] = {n: [] for n in envs}
    for i in range(warmup + repeats):
        for name, env in envs.items():
            env.reset(setup.start)
            t0 = time.perf_counter()
            env.step(setup.chunk)
            dt = time.perf_counter() - t0
            if i >= warmup:
                times[name].append(dt * 1000.0)
    return times


def run_chunk_latency(
    models: dict[str, str], *, rig: str | Path, task: str = "sort_cubes", repeats: int = 20, warmup: int = 2
) -> dict[str, Any]:
    from pilworld.world_model.loader import adapter_names, load_world_model

    if repeats < 1:
        raise ValueError(f"--repeats: expected at least 1, got {repeats}")
    setup = round_setup(rig, task)
    envs = {}
    for name, path in models.items():
        adapter = task if task in adapter_names(path) else None
        envs[name] = imagined_env(load_world_model(path, adapter=adapter), setup)
    times = time_rounds(envs, setup, repeats=repeats, warmup=warmup)
    first = next(iter(times))
    med = {n: float(np.median(t)) for n, t in times.items()}
    return {
        "bench": "chunk-latency",
        "machine": f"{platform.machine()}, {__import__('os').cpu_count()} CPUs, {platform.python_version()}",
        "task": task,
        "repeats": repeats,
        "models": {
            n: {
                "path": models[n],
                "median_ms": round(med[n], 1),
                "p90_ms": round(float(np.percentile(times[n], 90)), 1),
                "ratio_to_first": round(med[n] / med[first], 3),
            }
            for n in times
        },
        "reference": first,
    }


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        "--models",
        default="",
        help="NAME=FOLDER,... (default: v1 = sim_small, v2 = the shipped sim_composite); ratios to the first",
    )
    add_rig(parser)
    parser.add_argument(
        "--task", default="sort_cubes", help="task of the start and of the adapter (default sort_cubes)"
    )
    parser.add_argument("--repeats", type=int, default=20, help="timed rounds per model; the median is reported")
    add_json(parser)


def run(args: argparse.Namespace) -> int:
    """One line per model: median and p90 of a round, and its ratio to the first model."""
    # Imported here: the package's checkpoints pull in the model code, which parsing the options does not need.
    from pilworld.world_model import DEFAULT_CHECKPOINT, V1_CHECKPOINT

    text = args.models or f"v1={V1_CHECKPOINT},v2={DEFAULT_CHECKPOINT}"
    result = run_chunk_latency(parse_models(text), rig=args.rig, task=args.task, repeats=args.repeats)
    lines = [
        f"{name:>12}: median {m['median_ms']:.1f} ms, p90 {m['p90_ms']:.1f} ms, ×{m['ratio_to_first']:.2f}"
        for name, m in result["models"].items()
    ]
    return emit(args, result, lines)
