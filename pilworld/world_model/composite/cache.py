"""Training samples of world model v2: candidate layers and targets, built once and stored on disk.

A sample is one (clip, view, future frame k): the layers of :mod:`.layers` and the true frame,
area-downsampled to the network's working resolution, plus the frame's flags and the gripper
openings the robot measured there. Building a clip's layers costs ~0.1 s (Γ⁺ render and prior), so
they are computed once into ``numpy`` memmaps under ``CACHE/`` and reused by every training step and
every resumed run. Which clips and frames go in is a pure function of the seed, so a rebuilt cache is
identical; a cache whose recorded settings differ from the requested ones is refused.
"""

from __future__ import annotations

import json
import os
from collections.abc import Sequence
from concurrent.futures import ProcessPoolExecutor
from dataclasses import asdict, dataclass
from multiprocessing import get_all_start_methods, get_context
from pathlib import Path
from typing import Any

import cv2
import numpy as np
from numpy.typing import NDArray
from tqdm import tqdm

from pilworld.types import ARM_LAYOUT

# prior 3 + valid 1, current 3, carry L 3 + 1, carry R 3 + 1, parts one-hot 4, shade 1, depth 1, memory 3 + valid 1,
# hand region 1
BASE_CHANNELS = 26
MEMORY_FRAMES = 15  # history frames the memory looks back over (one round: K frames)
SCALARS = 8  # holding L/R, released L/R, k/K, view index, commanded grips L/R
DEPTH_SCALE = 2.0  # metres mapped to 255
GRIPS = [ARM_LAYOUT["left"][1], ARM_LAYOUT["right"][1]]
LAYERS_VERSION = 4  # bump when pilworld.world_model.composite.layers changes what it computes


@dataclass(frozen=True)
class CacheSpec:
    data: str
    rig: str
    size: int = 64  # working resolution
    frames_per_clip: int = 5  # future frames kept per clip and view
    max_clips: int = 3000  # clips drawn (without replacement, seeded) from the dataset's index (window 3)
    seed: int = 0
    layers_version: int = LAYERS_VERSION  # a cache made by other layer code is refused, not silently reused


def chunk_channels(
    layers: Any, current: dict[str, NDArray[np.uint8]], views: Sequence[str]
) -> tuple[NDArray[np.uint8], NDArray[np.float32]]:
    """Base channels (V·K, BASE_CHANNELS, H, W) uint8 and scalars (V·K, SCALARS) of one chunk, view-major.

    The one definition of the network's input layout: inference uses it at full resolution, the cache
    area-downsamples its rows.
    """
    K = layers.poses.shape[0]
    rows, scal = [], []
    for vi, v in enumerate(views):
        parts = layers.parts[v]
        size = parts.shape[1:]
        chans = np.concatenate(
            [
                layers.prior[v].transpose(0, 3, 1, 2),
                (layers.prior_valid[v] * np.uint8(255))[:, None].astype(np.uint8),
                np.broadcast_to(np.asarray(current[v]).transpose(2, 0, 1)[None], (K, 3, *size)),
                layers.carry["left"][v].transpose(0, 3, 1, 2),
                (layers.carry_valid["left"][v] * np.uint8(255))[:, None].astype(np.uint8),
                layers.carry["right"][v].transpose(0, 3, 1, 2),
                (layers.carry_valid["right"][v] * np.uint8(255))[:, None].astype(np.uint8),
                np.stack([(parts == p) * np.uint8(255) for p in (1, 2, 3, 4)], 1).astype(np.uint8),
                layers.shade[v][:, None],
                np.clip(layers.depth[v] / DEPTH_SCALE * 255, 0, 255).astype(np.uint8)[:, None],
                np.broadcast_to(layers.memory[v].transpose(2, 0, 1)[None], (K, 3, *size)),
                np.broadcast_to((layers.memory_valid[v] * np.uint8(255)).astype(np.uint8)[None, None], (K, 1, *size)),
                (layers.hands[v] * np.uint8(255)).astype(np.uint8)[:, None],
            ],
            1,
        )
        rows.append(chans)
        for k in range(K):
            scal.append(
                [
                    *layers.holding[k],
                    *layers.released[k],
                    (k + 1) / K,
                    vi,
                    layers.poses[k, GRIPS[0]],
                    layers.poses[k, GRIPS[1]],
                ]
            )
    return np.concatenate(rows, 0), np.asarray(scal, dtype=np.float32)


def downsampled(channels: NDArray[np.uint8], size: int) -> NDArray[np.uint8]:
    """(C, H, W) uint8 → (C, size, size), area-averaged one channel at a time (OpenCV rounds a many-channel
    resize differently, by ±1, from a one-channel one)."""
    return np.stack(
        [
            np.asarray(cv2.resize(np.ascontiguousarray(c), (size, size), interpolation=cv2.INTER_AREA), np.uint8)
            for c in channels
        ]
    )


_WORKER: dict[str, Any] = {}


def _clip_dataset(data: str) -> Any:
    """The dataset's clips with windows of 3 stride-frames (3× the paper's 9: more, overlapping clips)."""
    from pilworld.data.clip_dataset import ClipDataset
    from pilworld.data.clips import ClipSpec

    steps = ClipDataset(data).store.spec.steps_per_frame
    return ClipDataset(data, ClipSpec.for_dataset(steps, window=3, history=MEMORY_FRAMES))


def _init(spec: CacheSpec, rig: Any) -> None:
    import torch

    torch.set_num_threads(1)
    from pilworld.config.rig import RigConfig
    from pilworld.world_model.composite.layers import LayerBuilder

    _WORKER["ds"] = _clip_dataset(spec.data)
    _WORKER["lb"] = LayerBuilder(rig if rig is not None else RigConfig.load(spec.rig))
    _WORKER["spec"] = spec


def _build(
    job: tuple[int, int, list[int]],
) -> tuple[int, NDArray[np.uint8], NDArray[np.uint8], NDArray[np.float32], NDArray[np.float32]]:
    row, clip_index, ks = job
    ds, lb, spec = _WORKER["ds"], _WORKER["lb"], _WORKER["spec"]
    it = ds[clip_index]
    clip = ds.clips[clip_index]
    state_all, _, _ = ds._episode_vectors(clip.episode_index)
    fut_idx = ds.spec.future_indices(clip.t)
    views = ds.views
    cur = {v: np.moveaxis(it["current"][j].numpy(), 0, -1) for j, v in enumerate(views)}
    fut = {v: np.moveaxis(it["future"][j].numpy(), 1, -1) for j, v in enumerate(views)}
    head = views.index("cam_high")
    hist_idx, _ = ds.spec.history_indices(clip.t)
    layers = lb(
        cur,
        it["state"].numpy(),
        it["actions"].numpy(),
        {"cam_high": np.moveaxis(it["history"][head].numpy(), 1, -1)},
        state_all[hist_idx],
        it["history_valid"].numpy(),
    )
    K = layers.poses.shape[0]
    base, sca_all = chunk_channels(layers, cur, views)
    n = len(ks) * len(views)
    inp = np.empty((n, BASE_CHANNELS, spec.size, spec.size), np.uint8)
    tgt = np.empty((n, 3, spec.size, spec.size), np.uint8)
    sca = np.empty((n, SCALARS), np.float32)
    grip = np.empty((n, 2), np.float32)
    i = 0
    for vi, v in enumerate(views):
        for k in ks:
            inp[i] = downsampled(base[vi * K + k], spec.size)
            tgt[i] = cv2.resize(fut[v][k], (spec.size, spec.size), interpolation=cv2.INTER_AREA).transpose(2, 0, 1)
            sca[i] = sca_all[vi * K + k]
            grip[i] = state_all[fut_idx[k], GRIPS]
            i += 1
    return row, inp, tgt, sca, grip


def _jobs(spec: CacheSpec, ds: Any) -> list[tuple[int, int, list[int]]]:
    """The (row, clip, frames) of every cached clip: a pure function of the seed (the extras reuse it)."""
    rng = np.random.default_rng(spec.seed)
    clips = np.sort(rng.choice(len(ds), min(spec.max_clips, len(ds)), replace=False))
    K = ds.spec.future
    return [
        (r, int(c), sorted(rng.choice(K, spec.frames_per_clip, replace=False).tolist())) for r, c in enumerate(clips)
    ]


def _init_in(env: dict[str, str], init: Any, initargs: tuple[Any, ...]) -> None:
    """A worker's initializer: this process's environment (``PILWORLD_CACHE`` and the like), then ``init``."""
    os.environ.clear()
    os.environ.update(env)
    init(*initargs)


_PRELOAD = [
    "pilworld.world_model.composite.cache",
    "pilworld.world_model.composite.layers",
    "pilworld.data.clip_dataset",
]


def _fill(
    arrays: Sequence[Any],
    build: Any,
    init: Any,
    initargs: tuple[Any, ...],
    jobs: list[tuple[int, int, list[int]]],
    per: int,
    *,
    workers: int,
    chunksize: int,
    desc: str,
    progress: bool,
) -> None:
    """Run ``build`` over the clip jobs in a pool of worker processes and write each clip's rows into ``arrays``
    (``build`` returns ``(row, *parts)``, one part per array, ``per`` samples each); then flush them.

    The workers start from a clean process (``forkserver``, else ``spawn``), never by forking this one: a process
    that has run threaded code can fork a child that blocks forever on a lock some thread held at the fork (seen:
    a process that had decoded the store's videos, FFmpeg's threads, hung every cache build after it).
    ``ProcessPoolExecutor`` raises ``BrokenProcessPool`` when a worker dies (killed for memory, a crash in native
    code) where ``multiprocessing.Pool`` waits forever for the lost clip."""
    method = "forkserver" if "forkserver" in get_all_start_methods() else "spawn"
    ctx = get_context(method)
    if method == "forkserver":
        # The server imports these once (no threads started yet); each worker forks from it without importing again.
        ctx.set_forkserver_preload(_PRELOAD)
    env = dict(os.environ)  # the server's environment is from when it started; the workers read this one's
    with ProcessPoolExecutor(
        max(1, workers), mp_context=ctx, initializer=_init_in, initargs=(env, init, initargs)
    ) as pool:
        for row, *parts in tqdm(
            pool.map(build, jobs, chunksize=chunksize),
            total=len(jobs),
            desc=desc,
            unit="clip",
            disable=not progress,
        ):
            sl = slice(row * per, (row + 1) * per)
            for array, part in zip(arrays, parts, strict=True):
                array[sl] = part
    for array in arrays:
        array.flush()


def build_cache(spec: CacheSpec, out: str | Path, *, rig: Any = None, workers: int = 2, progress: bool = True) -> Path:
    """Build (or reuse) the cache of ``spec`` in ``out``; returns the folder. ``rig``: a loaded RigConfig
    to use instead of loading ``spec.rig``."""
    root = Path(out)
    meta_path = root / "cache.json"
    want = asdict(spec)
    if meta_path.is_file():
        have = json.loads(meta_path.read_text())
        if have.get("spec") != want:
            raise ValueError(f"{root}: a cache with other settings exists ({have.get('spec')}); choose another folder")
        if have.get("complete"):
            return root
    root.mkdir(parents=True, exist_ok=True)
    ds = _clip_dataset(spec.data)
    jobs = _jobs(spec, ds)
    clips = [c for _, c, _ in jobs]
    views = len(ds.views)
    per = spec.frames_per_clip * views
    n = len(jobs) * per
    s = spec.size
    mm = {
        "inputs": np.lib.format.open_memmap(root / "inputs.npy", "w+", np.uint8, (n, BASE_CHANNELS, s, s)),
        "targets": np.lib.format.open_memmap(root / "targets.npy", "w+", np.uint8, (n, 3, s, s)),
        "scalars": np.lib.format.open_memmap(root / "scalars.npy", "w+", np.float32, (n, SCALARS)),
        "grips": np.lib.format.open_memmap(root / "grips.npy", "w+", np.float32, (n, 2)),
    }
    episodes = np.repeat(np.array([ds.clips[c].episode_index for c in clips]), per)
    np.save(root / "episodes.npy", episodes)
    meta_path.write_text(json.dumps({"spec": want, "complete": False, "samples": n}))
    arrays = [mm["inputs"], mm["targets"], mm["scalars"], mm["grips"]]  # _build's order
    _fill(
        arrays, _build, _init, (spec, rig), jobs, per, workers=workers, chunksize=4, desc="v2 cache", progress=progress
    )
    meta_path.write_text(json.dumps({"spec": want, "complete": True, "samples": n, "views": list(ds.views)}))
    return root


# ---------------------------------------------------------------------------------------------- variant extras

EXTRAS = ("markers", "actions")  # what the recipe's equal-budget variants add to the inputs (switches.py)


def _init_extras(spec: CacheSpec, rig: Any) -> None:
    from pilworld.config.rig import RigConfig
    from pilworld.control_video.gamma import ControlVideo
    from pilworld.types import ChunkSpec

    _WORKER["ds"] = _clip_dataset(spec.data)
    rig_cfg = rig if rig is not None else RigConfig.load(spec.rig)
    _WORKER["gamma"] = ControlVideo.from_rig(rig_cfg, ChunkSpec(frames=_WORKER["ds"].spec.future))
    _WORKER["spec"] = spec


def _build_extras(job: tuple[int, int, list[int]]) -> tuple[int, NDArray[np.uint8], NDArray[np.float32]]:
    row, clip_index, ks = job
    ds, gamma, spec = _WORKER["ds"], _WORKER["gamma"], _WORKER["spec"]
    it = ds[clip_index]
    actions = it["actions"].numpy().astype(np.float64)
    # The paper's Γ as the imagined branch draws it: the stride-aligned actions, the trace from the current state.
    control = gamma.render_stride_aligned(actions[None], it["state"].numpy()[None])[0]
    views = ds.views
    n = len(ks) * len(views)
    markers = np.zeros((n, 3, spec.size, spec.size), np.uint8)
    acts = np.empty((n, 14), np.float32)
    i = 0
    for v in views:
        for k in ks:
            if v == "cam_high":
                markers[i] = downsampled(control[k].transpose(2, 0, 1), spec.size)
            acts[i] = actions[k]
            i += 1
    return row, markers, acts


def has_extras(cache: str | Path) -> bool:
    meta = Path(cache) / "extras.json"
    return meta.is_file() and bool(json.loads(meta.read_text()).get("complete"))


def build_extras(
    spec: CacheSpec, cache: str | Path, *, rig: Any = None, workers: int = 2, progress: bool = True
) -> Path:
    """Add the variants' per-sample inputs to a complete cache of ``spec``: the head view's marker Γ at the
    cache's size (``markers.npy``, zero in the wrist views) and the commanded action of each sample's frame
    (``actions.npy``). Same clips and frames as the cache (:func:`_jobs`); idempotent."""
    root = Path(cache)
    meta = json.loads((root / "cache.json").read_text()) if (root / "cache.json").is_file() else {}
    if not meta.get("complete") or meta.get("spec") != asdict(spec):
        raise ValueError(f"{root}: no complete cache of these settings to add the variant inputs to")
    if has_extras(root):
        return root
    ds = _clip_dataset(spec.data)
    jobs = _jobs(spec, ds)
    per = spec.frames_per_clip * len(ds.views)
    n = len(jobs) * per
    s = spec.size
    markers = np.lib.format.open_memmap(root / "markers.npy", "w+", np.uint8, (n, 3, s, s))
    actions = np.lib.format.open_memmap(root / "actions.npy", "w+", np.float32, (n, 14))
    _fill(
        [markers, actions],
        _build_extras,
        _init_extras,
        (spec, rig),
        jobs,
        per,
        workers=workers,
        chunksize=8,
        desc="v2 cache: variant inputs",
        progress=progress,
    )
    (root / "extras.json").write_text(json.dumps({"complete": True, "extras": list(EXTRAS), "samples": n}))
    return root
