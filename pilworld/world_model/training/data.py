"""Training data for the world model: frames for the VAE, latent clips for Ψ_θ, and a step-indexed order.

**Data order is a pure function of (seed, step, rank)**: every batch draws its clip indices from a
generator seeded by the step number, so a run killed at step s and resumed from its checkpoint sees
exactly the batches an uninterrupted run would, with no sampler state to save. Under ``torchrun``
each rank takes its own slice of the same global draw.

Ψ_θ trains on **latents**: once the VAE is trained and frozen, every frame a clip uses is encoded
once (``latents/`` in the run folder, float16), so a training step never runs the VAE encoder.
"""

from __future__ import annotations

import functools
import hashlib
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import torch
from numpy.typing import NDArray
from tqdm import tqdm

from pilworld.config.rig import RigConfig
from pilworld.data.clip_dataset import ClipDataset, save_npy
from pilworld.data.clips import ClipSpec, mix_weights
from pilworld.io.atomic import atomic_write
from pilworld.world_model.base import WorldModelBatch
from pilworld.world_model.batching import collate_clips, control_renderer, resize_images
from pilworld.world_model.latent.model import PilWorldModel
from pilworld.world_model.latent.vae import to_unit


def step_generator(seed: int, step: int, rank: int = 0, stream: int = 0) -> torch.Generator:
    """A generator determined by (seed, step, rank, stream) only — the basis of exact resume."""
    key = hashlib.sha256(f"{seed}/{step}/{rank}/{stream}".encode()).digest()
    return torch.Generator().manual_seed(int.from_bytes(key[:8], "little") & ((1 << 63) - 1))


def is_validation_episode(episode: int, every: int) -> bool:
    """Every ``every``-th episode (by index) is held out for validation; 0 disables the split."""
    return every > 0 and episode % every == every - 1


@dataclass(frozen=True)
class LatentBatch:
    """Ψ_θ's training inputs for a batch of clips (normalised latents, float32)."""

    current: torch.Tensor  # [B, V, C, h, w]
    history: torch.Tensor  # [B, V, H_h, C, h, w]
    future: torch.Tensor  # [B, V, K, C, h, w]
    history_valid: torch.Tensor  # bool [B, H_h]
    control: torch.Tensor  # uint8 [B, K, 3, H, W]
    actions: torch.Tensor  # [B, K, A]
    instruction: list[str]


@dataclass(frozen=True)
class DataSelection:
    """Which clips of a dataset a stage trains on."""

    tasks: tuple[str, ...] = ()  # instructions or simulated task names; empty = all
    success_fraction: float | None = None  # share of clips from successful episodes (None = as stored)
    val_every: int = 20  # every n-th episode is validation (never trained on)
    window: int = 9  # clip window W (stride-sampled frames between clip starts; the paper's 9)


class TrainData:
    """Clips of one dataset, split into train/validation episodes, with the VAE's frames and Ψ_θ's latents."""

    def __init__(self, root: str | Path, rig: RigConfig, model: PilWorldModel, selection: DataSelection) -> None:
        store_probe = ClipDataset(root)
        spec = ClipSpec.for_dataset(
            store_probe.store.spec.steps_per_frame,
            future=model.config.future,
            history=model.config.history,
            window=selection.window,
        )
        self.dataset = ClipDataset(root, spec, views=list(model.config.views))
        self.model = model
        self.selection = selection
        self.gamma = control_renderer(rig, model.info)
        episodes = self.dataset.store.episodes
        names = self._task_names(episodes)
        # A task may be named by its simulated task name or by its instruction. (Episode rows hold the
        # instruction in LeRobot's ``tasks`` list, not in a ``task`` key: reading ``task`` matched nothing.)
        instructions = [self._instruction(ep) for ep in episodes]
        wanted = set(selection.tasks)
        if wanted:
            known = set(names)
            unknown = sorted(wanted - known - set(instructions))
            if unknown:
                raise ValueError(f"tasks: {unknown} not in {root} (has {sorted(known)})")
        keep_train: list[int] = []
        keep_val: list[int] = []
        for i, clip in enumerate(self.dataset.clips):
            e = clip.episode_index
            if wanted and names[e] not in wanted and instructions[e] not in wanted:
                continue
            (keep_val if is_validation_episode(e, selection.val_every) else keep_train).append(i)
        if not keep_train:
            raise ValueError(f"{root}: no training clips for tasks {sorted(wanted) or 'all'}")
        self.train_clips = np.array(keep_train, dtype=np.int64)
        self.val_clips = np.array(keep_val, dtype=np.int64)
        success = self.dataset.clip_success()[self.train_clips]
        self.weights = torch.from_numpy(mix_weights(success, selection.success_fraction))
        self._latents: dict[tuple[int, str], NDArray[np.float16]] = {}

    @staticmethod
    def _task_names(episodes: list[dict[str, object]]) -> list[str]:
        """The task name of each episode when recorded by our collector (``extra.task``, older data
        ``extra.sim_task``), else its instruction."""
        out = []
        for ep in episodes:
            extra = ep.get("extra")
            name = None
            if isinstance(extra, str) and ('"task"' in extra or '"sim_task"' in extra):
                import json

                extra = json.loads(extra)
            if isinstance(extra, dict):
                name = extra.get("task") or extra.get("sim_task")
            out.append(str(name or TrainData._instruction(ep)))
        return out

    @staticmethod
    def _instruction(episode: dict[str, object]) -> str:
        """The instruction of an episodes-table row (its LeRobot ``tasks`` list; "" when absent)."""
        tasks = episode.get("tasks")
        return str(tasks[0]) if isinstance(tasks, list) and tasks else ""

    # ------------------------------------------------------------------ orders

    def clip_indices(self, seed: int, step: int, batch: int, rank: int = 0, world: int = 1) -> NDArray[np.int64]:
        """This rank's dataset clip indices for a step (the global draw of ``batch`` sliced by rank)."""
        gen = step_generator(seed, step)
        draw = torch.multinomial(self.weights, batch, replacement=True, generator=gen).numpy()
        out: NDArray[np.int64] = self.train_clips[draw[rank::world]]
        return out

    def frame_batch(self, seed: int, step: int, batch: int, rank: int = 0, world: int = 1) -> torch.Tensor:
        """uint8 [b, 3, H, W]: random frames of random views of training clips (the VAE's data)."""
        gen = step_generator(seed, step, stream=1)
        clips = self.train_clips[torch.randint(len(self.train_clips), (batch,), generator=gen).numpy()]
        views = torch.randint(len(self.dataset.views), (batch,), generator=gen).numpy()
        picks = torch.randint(1 << 30, (batch,), generator=gen).numpy()
        frames = []
        for c, v, r in list(zip(clips, views, picks, strict=True))[rank::world]:
            ref = self.dataset.clips[int(c)]
            cached, _ = self.dataset.frames_of(ref.episode_index, self.dataset.views[int(v)])
            frames.append(np.asarray(cached[int(r) % len(cached)]))
        x = torch.from_numpy(np.ascontiguousarray(np.moveaxis(np.stack(frames), -1, -3)))
        return resize_images(x, self.model.config.height, self.model.config.width)

    # ------------------------------------------------------------------ latents

    def build_latents(self, folder: Path, progress: bool = True, batch: int = 64) -> None:
        """Encode every frame any selected clip uses with the frozen VAE (once; reused on resume)."""
        folder.mkdir(parents=True, exist_ok=True)
        episodes = sorted(
            {self.dataset.clips[int(i)].episode_index for i in np.concatenate([self.train_clips, self.val_clips])}
        )
        cfg = self.model.config
        self.model.eval()
        for e in tqdm(episodes, desc="encoding latents", unit="episode", disable=not progress):
            for v in self.dataset.views:
                path = folder / f"ep{e:06d}-{v}.npy"
                if not path.is_file():
                    frames, _ = self.dataset.frames_of(e, v)
                    parts = []
                    with torch.no_grad():
                        for s in range(0, len(frames), batch):
                            x = torch.from_numpy(
                                np.ascontiguousarray(np.moveaxis(np.asarray(frames[s : s + batch]), -1, -3))
                            )
                            parts.append(self.model.encode(resize_images(x, cfg.height, cfg.width)).half().numpy())
                    z = np.concatenate(parts)
                    atomic_write(path, functools.partial(save_npy, array=z), durable=False)
                self._latents[(e, v)] = np.load(path, mmap_mode="r", allow_pickle=False)

    def latent_stats(self, seed: int, samples: int = 512) -> tuple[list[float], list[float]]:
        """Per-channel mean and std of raw VAE latents over random training frames (for normalisation)."""
        x = self.frame_batch(seed, 0, samples)
        with torch.no_grad():
            mean, _ = self.model.vae.encode(to_unit(x))
        return mean.mean(dim=(0, 2, 3)).tolist(), mean.std(dim=(0, 2, 3)).clamp_min(1e-3).tolist()

    def latent_batch(self, clip_indices: NDArray[np.int64]) -> LatentBatch:
        """Latents and conditions of clips (needs :meth:`build_latents` first)."""
        items = []
        spec = self.dataset.spec
        for i in clip_indices:
            ref = self.dataset.clips[int(i)]
            e, t = ref.episode_index, ref.t
            hist, valid = spec.history_indices(t)
            fut = spec.future_indices(t)
            per_view = {"current": [], "history": [], "future": []}  # type: dict[str, list[NDArray[np.float16]]]
            for v in self.dataset.views:
                _, row = self.dataset.frames_of(e, v)
                z = self._latents[(e, v)]
                per_view["current"].append(z[row[t]])
                per_view["history"].append(z[row[hist]])
                per_view["future"].append(z[row[fut]])
            state, action, instruction = self.dataset._episode_vectors(e)
            items.append(
                {
                    "current": np.stack(per_view["current"]),
                    "history": np.stack(per_view["history"]),
                    "future": np.stack(per_view["future"]),
                    "valid": valid,
                    "actions": action[spec.action_indices(t)],
                    "state": state[t],
                    "instruction": instruction,
                }
            )
        actions = np.stack([it["actions"] for it in items]).astype(np.float64)
        control = self.gamma.render_stride_aligned(actions, np.stack([it["state"] for it in items]))

        def stack(key: str) -> torch.Tensor:
            return torch.from_numpy(np.stack([it[key] for it in items]).astype(np.float32))

        return LatentBatch(
            current=stack("current"),
            history=stack("history"),
            future=stack("future"),
            history_valid=torch.from_numpy(np.stack([it["valid"] for it in items])),
            control=torch.from_numpy(np.ascontiguousarray(np.moveaxis(control, -1, -3))),
            actions=torch.from_numpy(actions.astype(np.float32)),
            instruction=[str(it["instruction"]) for it in items],
        )

    def val_batch(self, count: int, seed: int) -> WorldModelBatch:
        """A fixed set of validation clips as images (for PSNR/SSIM after decoding)."""
        pool = self.val_clips if len(self.val_clips) else self.train_clips
        gen = np.random.default_rng(seed)
        picks = gen.choice(pool, size=min(count, len(pool)), replace=False)
        batch = collate_clips([self.dataset[int(i)] for i in picks], self.gamma)
        cfg = self.model.config
        for name in ("current", "history", "future"):
            setattr(batch, name, resize_images(getattr(batch, name), cfg.height, cfg.width))
        return batch
