"""``pilworld bench world-model-presets``: parameter counts and chunk latency of every native preset.

Weights are random (latency does not depend on their values); each preset runs at its own image size
and default Euler steps, K = 15 frames × 3 views, batch 1, the same ``predict`` call the imagined branch
makes. Accuracy needs trained weights: see ``pilworld bench world-model``.
"""

from __future__ import annotations

import argparse
import time
from collections.abc import Sequence
from typing import Any

import numpy as np
import torch
from tqdm import tqdm

from pilworld.bench.common import machine_info
from pilworld.bench.flags import add_json
from pilworld.bench.output import emit
from pilworld.world_model.base import PredictRequest
from pilworld.world_model.latent.config import PRESETS, preset
from pilworld.world_model.latent.model import PilWorldModel

CONTROL_STRIDE = 3  # Δ
CONTROL_RATE_HZ = 30.0  # the simulated rig


def _count(module: torch.nn.Module) -> int:
    return int(sum(p.numel() for p in module.parameters()))


def _request(model: PilWorldModel, seed: int) -> PredictRequest:
    info = model.info
    rng = np.random.default_rng(seed)

    def frames(*lead: int) -> np.ndarray[Any, np.dtype[np.uint8]]:
        return rng.integers(0, 256, (*lead, info.height, info.width, 3), dtype=np.uint8)

    return PredictRequest.build(
        info,
        current={v: frames() for v in info.views},
        history={v: frames(info.history) for v in info.views},
        control=frames(info.future),
        actions=np.zeros((info.future, info.action_dim), dtype=np.float32),
        instruction="sort the cubes by size.",
    )


def run_presets_bench(
    names: Sequence[str] | None = None, *, repeats: int = 10, steps: int | None = None, progress: bool = True
) -> dict[str, Any]:
    names = list(names or PRESETS)
    out: dict[str, Any] = {"bench": "world-model-presets", "presets": {}}
    for name in tqdm(names, desc="presets", unit="preset", disable=not progress):
        with torch.random.fork_rng():
            torch.manual_seed(0)
            model = PilWorldModel(preset(name)).eval()
        req = _request(model, 0)
        n_steps = steps or model.config.steps
        times = []
        for r in range(2 + repeats):
            t = time.perf_counter()
            model.predict(req, steps=n_steps, seed=r)
            if r >= 2:
                times.append(time.perf_counter() - t)
        latency = float(np.median(times))
        chunk_s = model.info.future * CONTROL_STRIDE / CONTROL_RATE_HZ
        out["presets"][name] = {
            "params": _count(model),
            "params_vae": _count(model.vae),
            "params_denoiser": _count(model.denoiser),
            "image_size": [model.info.width, model.info.height],
            "views": len(model.info.views),
            "K": model.info.future,
            "steps": n_steps,
            "chunk_latency_ms": round(latency * 1000, 2),
            "realtime_factor": round(chunk_s / latency, 2),
            "float32_mb": round(_count(model) * 4 / 1e6, 1),
        }
    out.update({"torch_threads": torch.get_num_threads(), "torch": torch.__version__, "machine": machine_info()})
    return out


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--presets", default="", help="comma-separated presets (default: all)")
    parser.add_argument("--repeats", type=int, default=10, help="timed calls per preset; the median is reported")
    parser.add_argument("--steps", type=int, default=None, help="Euler steps (default: each preset's own)")
    add_json(parser)


def run(args: argparse.Namespace) -> int:
    """One line per preset: size, parameters, steps, chunk latency and realtime factor."""
    names = [n for n in args.presets.split(",") if n] or None
    result = run_presets_bench(names, repeats=args.repeats, steps=args.steps, progress=not args.json)
    lines = []
    for name, r in result["presets"].items():
        w, h = r["image_size"]
        lines.append(
            f"{name:>6}: {r['params'] / 1e6:6.2f} M params ({r['float32_mb']} MB float32), {w}x{h}, "
            f"{r['steps']} steps: {r['chunk_latency_ms']:.1f} ms per chunk, realtime x{r['realtime_factor']}"
        )
    return emit(args, result, lines)
