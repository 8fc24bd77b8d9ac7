"""``pilworld bench control-video --style S`` for Γ⁺ styles: latency of one chunk beside the world model's.

One chunk of Γ⁺ is what the imagined branch computes once per round: K = 15 stride-aligned actions in the
three views at the rig's image size (what the world model consumes), the prior included when the style
has one. Starts are held-out simulated layouts (seeds ≥ 1,000,000) and chunks are smooth random motions
from each start's state, so the renderer sees what a policy produces (arms moving in and out of view,
grippers opening and closing). Γ⁺ runs in one process with one OpenCV thread, as a rollout worker does.

The acceptance figure is a **ratio measured in the same run**: Γ⁺'s median chunk time over the shipped
world model's median chunk latency (its ``predict`` on one request, with torch's default threads, as
``pilworld bench world-model`` measures it). Our machines differ up to 2× in absolute speed; the ratio
does not.
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path
from typing import Any

import cv2
import numpy as np
from numpy.typing import NDArray
from tqdm import tqdm

from pilworld.bench.common import machine_info
from pilworld.bench.output import emit
from pilworld.config.rig import RigConfig
from pilworld.control_video.examples import random_chunks, starting_at
from pilworld.control_video.gamma_plus import GammaPlus
from pilworld.control_video.robot_render import Backend
from pilworld.control_video.styles import Style
from pilworld.options.parse import parse_size
from pilworld.types import ChunkSpec, Observation
from pilworld.world_model import V1_CHECKPOINT

SHIPPED_MODEL = V1_CHECKPOINT  # the model this bench was first measured with
HELD_OUT_SEED = 1_000_000


def sim_starts(rig: RigConfig, n: int, task: str = "sort_cubes") -> list[Observation]:
    """``n`` start observations of held-out layouts (seeds 1,000,000 + i) on the simulated rig."""
    from simrig.robot import SimRobot

    sim = SimRobot(rig, task)
    sim.connect()
    try:
        out = []
        for i in range(n):
            sim.reset(seed=HELD_OUT_SEED + i, subtask=0, history=0)
            out.append(sim.observe())
        return out
    finally:
        sim.disconnect()


def chunks_from(state: NDArray[np.floating], n: int, spec: ChunkSpec, seed: int) -> NDArray[np.float64]:
    """(n, H, 14) smooth random chunks that start at ``state`` (offsets of random_chunks from home)."""
    out: NDArray[np.float64] = starting_at(random_chunks(n, spec.horizon, seed=seed), state).astype(np.float64)
    return out


class WorldModelTimer:
    """Times a world-model folder's ``predict`` on one request (its shape, random content)."""

    def __init__(self, model_dir: Path) -> None:
        import torch

        from pilworld.world_model.base import PredictRequest
        from pilworld.world_model.loader import load_world_model

        self.torch = torch
        self.model_dir = model_dir
        self.model = load_world_model(model_dir)
        info = self.model.info
        rng = np.random.default_rng(0)
        H, W, K = info.height, info.width, info.future
        self.image_size = [W, H]
        self.request = PredictRequest.build(
            info,
            current={v: rng.integers(0, 256, (H, W, 3), dtype=np.uint8) for v in info.views},
            history={v: rng.integers(0, 256, (info.history, H, W, 3), dtype=np.uint8) for v in info.views},
            control=rng.integers(0, 256, (K, H, W, 3), dtype=np.uint8),
            actions=np.zeros((K, info.action_dim), dtype=np.float32),
            instruction="sort the cubes",
        )
        self.times: list[float] = []
        self.time(2, record=False)  # warm-up

    def time(self, calls: int, *, record: bool = True) -> None:
        with self.torch.no_grad():
            for _ in range(calls):
                t = time.perf_counter()
                self.model.predict(self.request)
                if record:
                    self.times.append(time.perf_counter() - t)

    def summary(self) -> dict[str, Any]:
        return {
            "model": str(self.model_dir),
            "chunk_latency_ms": 1e3 * float(np.median(self.times)),
            "image_size": self.image_size,
            "torch_threads": self.torch.get_num_threads(),
            "calls": len(self.times),
        }


def run_gamma_plus_bench(
    rig_path: Path,
    style: str,
    *,
    backend: Backend = "analytic",
    starts: int = 4,
    chunks_per_start: int = 10,
    repeats: int = 3,
    world_model: Path | None = SHIPPED_MODEL,
    world_model_repeats: int = 10,
    size: tuple[int, int] | None = None,
    spec: ChunkSpec | None = None,
    seed: int = 0,
    progress: bool = True,
) -> dict[str, Any]:
    """Γ⁺ chunk latency per style (best of ``repeats`` passes of the median), the world model's beside it."""
    parsed = Style.parse(style)
    if starts < 1 or chunks_per_start < 1 or repeats < 1:
        raise ValueError(
            f"starts, chunks_per_start and repeats must be ≥ 1, got {starts}, {chunks_per_start}, {repeats}"
        )
    spec = spec or ChunkSpec()
    rig = RigConfig.load(rig_path)
    if size is not None:
        rig = RigConfig.model_validate({**rig.model_dump(), "image_size": {"width": size[0], "height": size[1]}})
    cv2.setNumThreads(1)  # one process, one thread: the figure a rollout worker gets
    gamma = GammaPlus(rig, parsed, spec=spec, backend=backend)
    obs = sim_starts(rig, starts)
    work = [(o, c) for i, o in enumerate(obs) for c in chunks_from(o.state, chunks_per_start, spec, seed + i)]
    gamma(work[0][1], previous_state=work[0][0].state, current_images=work[0][0].images)  # warm-up

    # The world model is timed between Γ⁺'s passes, so both see the same load on a shared machine.
    timer = WorldModelTimer(world_model) if world_model is not None else None
    passes = []
    robot_fraction: dict[str, list[float]] = {v: [] for v in gamma.views}
    prior_valid: dict[str, list[float]] = {v: [] for v in gamma.views}
    for r in tqdm(range(repeats), desc=f"bench control-video {parsed.name}", unit="pass", disable=not progress):
        times = []
        for o, chunk in work:
            t = time.perf_counter()
            out = gamma(chunk, previous_state=o.state, current_images=o.images)
            times.append(time.perf_counter() - t)
            if r == 0:
                for v in gamma.views:
                    if out.render is not None:
                        robot_fraction[v].append(float(np.mean(out.render.parts[v] > 0)))
                    if out.prior is not None:
                        prior_valid[v].append(float(np.mean(out.prior.valid[v])))
        passes.append(times)
        if timer is not None:
            timer.time(max(1, world_model_repeats // repeats))
    medians = [float(np.median(t)) for t in passes]
    best = int(np.argmin(medians))
    result: dict[str, Any] = {
        "benchmark": "control-video",
        "style": parsed.name,
        "backend": backend if (parsed.render or parsed.prior) else None,
        "views": list(gamma.views),
        "image_size": [rig.image_size.width, rig.image_size.height],
        "K": spec.frames,
        "stride": spec.stride,
        "chunks": len(work),
        "repeats": repeats,
        "ms_per_chunk_p50": 1e3 * medians[best],
        "ms_per_chunk_p90": 1e3 * float(np.percentile(passes[best], 90)),
        "frames_per_s": spec.frames * len(gamma.views) / medians[best],
        "robot_pixel_fraction": {v: float(np.mean(x)) for v, x in robot_fraction.items() if x},
        "prior_valid_fraction": {v: float(np.mean(x)) for v, x in prior_valid.items() if x},
        "opencv_threads": 1,
        "processes": 1,
        "rig": rig.name,
        **machine_info(),
    }
    if timer is not None:
        wm = timer.summary()
        result["world_model"] = wm
        result["ratio_to_world_model"] = result["ms_per_chunk_p50"] / wm["chunk_latency_ms"]
    return result


def run_style(args: argparse.Namespace, style: Style, spec: ChunkSpec) -> int:
    """``pilworld bench control-video`` for a Γ⁺ ``style`` (the options of :mod:`pilworld.bench.control_video`)."""
    model: Path | None = SHIPPED_MODEL if args.world_model is None else args.world_model
    if model is not None and str(model).lower() == "none":
        model = None
    result = run_gamma_plus_bench(
        args.rig,
        style.name,
        backend=args.backend,
        starts=args.starts,
        chunks_per_start=args.chunks_per_start,
        repeats=args.repeats,
        world_model=model,
        size=parse_size(args.size) if args.size else None,
        spec=spec,
        seed=args.seed,
        progress=not args.json,
    )
    line = (
        f"control-video {result['style']}: {result['ms_per_chunk_p50']:.1f} ms per chunk "
        f"(K={result['K']} × {len(result['views'])} views at {result['image_size'][0]}x{result['image_size'][1]})"
    )
    if "world_model" in result:
        line += (
            f"; world model {result['world_model']['chunk_latency_ms']:.1f} ms per chunk in the same run "
            f"(ratio {result['ratio_to_world_model']:.2f})"
        )
    return emit(args, result, [line])
