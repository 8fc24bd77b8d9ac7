"""A torch ``Dataset`` of training clips that decodes every video once.

Decoding H.264 is the bottleneck of naive loaders (every clip would decode up to 21 frames × 3
views). Here each (episode, view) video is decoded once, and only the frames some clip uses (about
one in Δ) are kept, in an uncompressed ``.npy`` cache file that later reads memory-map. The cache
lives in ``$PILWORLD_CACHE`` (default ``~/.cache/pilworld``) under a key of the dataset path, the
clip spec and each video file's size and mtime, so a re-encoded or appended dataset never reads
stale frames. DataLoader workers share the cache: a file is written to a temporary name and renamed.
"""

from __future__ import annotations

import hashlib
import os
from pathlib import Path
from typing import Any

import numpy as np
import torch
from numpy.typing import NDArray
from torch.utils.data import Dataset, WeightedRandomSampler
from tqdm import tqdm

from pilworld.data.clips import ClipRef, ClipSpec, index_clips, mix_weights
from pilworld.data.outcomes import read_outcomes
from pilworld.data.reader import EpisodeStore, list_column
from pilworld.data.spec import ACTION_KEY, STATE_KEY
from pilworld.io.atomic import atomic_write


def save_npy(path: Path, array: NDArray[Any]) -> None:
    with path.open("wb") as fh:  # a handle, so np.save does not append ".npy" to the temporary name
        np.save(fh, array, allow_pickle=False)


def default_cache_dir() -> Path:
    return Path(os.environ.get("PILWORLD_CACHE", Path.home() / ".cache" / "pilworld")).expanduser()


def episode_success(root: Path, num_episodes: int, judge: str | None) -> NDArray[np.int8]:
    """Per episode 1 / 0 / −1 (unknown) from the outcomes table.

    ``judge`` picks one judge id; ``None`` uses the majority over all judges of that episode (a tie
    counts as failure, since a disputed success is no evidence of success).
    """
    out = np.full(num_episodes, -1, dtype=np.int8)
    votes: dict[int, list[bool]] = {}
    for o in read_outcomes(root):
        if judge is None or o.judge_id == judge:
            votes.setdefault(o.episode_index, []).append(o.success)
    for e, v in votes.items():
        if e < num_episodes:
            out[e] = 1 if sum(v) * 2 > len(v) else 0
    return out


class ClipDataset(Dataset[dict[str, Any]]):
    """Clips of a dataset (see :mod:`pilworld.data.clips` for the indexing).

    Each item is a dict:

    * ``history`` uint8 [V, H_h, 3, H, W], ``history_valid`` bool [H_h]
    * ``current`` uint8 [V, 3, H, W], ``future`` uint8 [V, K, 3, H, W]
    * ``actions`` float32 [K, action_dim] (stride-aligned), ``state`` float32 [state_dim] (at t)
    * ``instruction`` str, ``success`` int (1, 0, −1 unknown), ``episode_index``, ``frame_index`` int

    Views are stacked in ``views`` order (default: the dataset's).
    """

    def __init__(
        self,
        root: str | Path,
        spec: ClipSpec | None = None,
        *,
        views: list[str] | None = None,
        cache_dir: str | Path | None = None,
        success_judge: str | None = None,
    ) -> None:
        self.store = EpisodeStore(root)
        # By default the paper's Δ = 3 control steps, in the dataset's stored frames.
        self.spec = spec or ClipSpec.for_dataset(self.store.spec.steps_per_frame)
        self.views = views or list(self.store.spec.views)
        unknown = [v for v in self.views if v not in self.store.spec.views]
        if unknown:
            raise ValueError(f"views: {unknown} not in {self.store.root} (has {list(self.store.spec.views)})")
        lengths = [int(r["length"]) for r in self.store.episodes]
        self.clips: list[ClipRef] = index_clips(lengths, self.spec)
        self.episode_success = episode_success(self.store.root, len(lengths), success_judge)
        key = f"{self.store.root.resolve()}|{self.spec}"
        self.cache_dir = Path(cache_dir or default_cache_dir()) / "clips" / hashlib.sha1(key.encode()).hexdigest()[:16]
        self._vectors: dict[int, tuple[NDArray[np.float32], NDArray[np.float32], str]] = {}
        self._frames: dict[tuple[int, str], tuple[NDArray[np.uint8], NDArray[np.int64]]] = {}

    def __len__(self) -> int:
        return len(self.clips)

    # ------------------------------------------------------------------ caches

    def needed_frames(self, episode: int) -> NDArray[np.int64]:
        """Sorted frame indices used by some clip of ``episode``."""
        length = int(self.store.episodes[episode]["length"])
        parts = [np.zeros(0, dtype=np.int64)]
        for t in self.spec.clip_starts(length):
            parts += [self.spec.history_indices(int(t))[0], np.array([t]), self.spec.future_indices(int(t))]
        return np.unique(np.concatenate(parts))

    def _cache_path(self, episode: int, view: str) -> Path:
        video, _ = self.store.video_file(episode, view)
        st = video.stat()
        return self.cache_dir / f"ep{episode:06d}-{view}-{st.st_size}-{int(st.st_mtime_ns)}.npy"

    def frames_of(self, episode: int, view: str) -> tuple[NDArray[np.uint8], NDArray[np.int64]]:
        """(cached frames (M, H, W, 3), row of each episode frame or −1) for one view of an episode."""
        hit = self._frames.get((episode, view))
        if hit is not None:
            return hit
        needed = self.needed_frames(episode)
        path = self._cache_path(episode, view)
        if not path.is_file():
            decoded = self.store.frames(episode, view)  # one decode of the whole video
            atomic_write(path, lambda tmp: save_npy(tmp, decoded[needed]), durable=False)
        frames = np.load(path, mmap_mode="r", allow_pickle=False)
        row = np.full(int(self.store.episodes[episode]["length"]), -1, dtype=np.int64)
        row[needed] = np.arange(len(needed))
        self._frames[(episode, view)] = (frames, row)
        return frames, row

    def _episode_vectors(self, episode: int) -> tuple[NDArray[np.float32], NDArray[np.float32], str]:
        hit = self._vectors.get(episode)
        if hit is None:
            table = self.store.frame_table(episode)
            task_index = int(table.column("task_index")[0].as_py())
            hit = (
                list_column(table, STATE_KEY, self.store.spec.state_dim),
                list_column(table, ACTION_KEY, self.store.spec.action_dim),
                self.store.tasks.get(task_index, ""),
            )
            self._vectors[episode] = hit
        return hit

    def warm_cache(self, progress: bool = True) -> None:
        """Decode every episode once now (otherwise it happens on first access)."""
        episodes = sorted({c.episode_index for c in self.clips})
        for e in tqdm(episodes, desc="decoding videos", unit="episode", disable=not progress):
            for v in self.views:
                self.frames_of(e, v)

    # ------------------------------------------------------------------ items

    def __getitem__(self, i: int) -> dict[str, Any]:
        clip = self.clips[i]
        e, t = clip.episode_index, clip.t
        hist, valid = self.spec.history_indices(t)
        fut = self.spec.future_indices(t)
        stacks: dict[str, list[NDArray[np.uint8]]] = {"history": [], "current": [], "future": []}
        for v in self.views:
            frames, row = self.frames_of(e, v)
            stacks["history"].append(frames[row[hist]])
            stacks["current"].append(frames[row[t]])
            stacks["future"].append(frames[row[fut]])
        state, action, instruction = self._episode_vectors(e)

        def chw(x: list[NDArray[np.uint8]]) -> torch.Tensor:
            return torch.from_numpy(np.ascontiguousarray(np.moveaxis(np.stack(x), -1, -3)))

        return {
            "history": chw(stacks["history"]),
            "history_valid": torch.from_numpy(valid),
            "current": chw(stacks["current"]),
            "future": chw(stacks["future"]),
            "actions": torch.from_numpy(action[self.spec.action_indices(t)].copy()),
            "state": torch.from_numpy(state[t].copy()),
            "instruction": instruction,
            "success": int(self.episode_success[e]),
            "episode_index": e,
            "frame_index": t,
        }

    # ------------------------------------------------------------------ sampling

    def clip_success(self) -> NDArray[np.int8]:
        return np.array([self.episode_success[c.episode_index] for c in self.clips], dtype=np.int8)

    def sampler(self, num_samples: int, success_fraction: float | None = None, seed: int = 0) -> WeightedRandomSampler:
        """A sampler drawing clips with the given success/failure mix (see :func:`mix_weights`)."""
        weights = mix_weights(self.clip_success(), success_fraction)
        gen = torch.Generator().manual_seed(seed)
        return WeightedRandomSampler(weights.tolist(), num_samples, replacement=True, generator=gen)
