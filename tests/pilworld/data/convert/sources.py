"""Tiny synthetic source datasets, written the way LeRobot (v2.1, packed v3.0) and ALOHA write theirs."""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import cv2
import h5py
import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq
from numpy.typing import NDArray

from pilworld.data.video_codec import encode_video

IMAGE_PREFIX = "observation.images."


def noise_frames(T: int, h: int, w: int, seed: int) -> NDArray[np.uint8]:
    """Random pixels: any codec error shows (only lossless round trips compare equal)."""
    return np.random.default_rng(seed).integers(0, 256, (T, h, w, 3), dtype=np.uint8)


def smooth_frames(T: int, h: int, w: int, seed: int) -> NDArray[np.uint8]:
    """Gradients plus a pure red square (top-left): JPEG-friendly, and a swapped R/B channel shows."""
    yy, xx = np.mgrid[0:h, 0:w]
    t = np.arange(T)[:, None, None]
    r = 40 + xx[None] * 3 + t * 2
    g = 50 + yy[None] * 3 + seed * 5 + 0 * t
    b = np.broadcast_to(120 + t, r.shape)
    out = np.stack([r, g, b], axis=-1).clip(0, 255).astype(np.uint8)
    out[:, : h // 4, : w // 4] = (230, 10, 10)
    return out


@dataclass
class SourceEpisode:
    images: dict[str, NDArray[np.uint8]]  # full LeRobot camera key → (T, H, W, 3)
    state: NDArray[np.float32]
    action: NDArray[np.float32]
    task_indices: list[int]  # per frame
    image_keys: tuple[str, ...] = ()  # cameras stored as PNG inside the parquet instead of an mp4

    @property
    def length(self) -> int:
        return int(self.state.shape[0])


def make_episodes(
    lengths: list[int], cameras: dict[str, tuple[int, int]], state_dim: int, action_dim: int, tasks: list[int]
) -> list[SourceEpisode]:
    eps = []
    for k, T in enumerate(lengths):
        rng = np.random.default_rng(100 + k)
        eps.append(
            SourceEpisode(
                images={cam: noise_frames(T, h, w, seed=10 * k + i) for i, (cam, (h, w)) in enumerate(cameras.items())},
                state=rng.standard_normal((T, state_dim)).astype(np.float32),
                action=rng.standard_normal((T, action_dim)).astype(np.float32),
                task_indices=[tasks[k % len(tasks)]] * T,
            )
        )
    return eps


def _vector(values: NDArray[np.float32]) -> pa.Array:
    return pa.array(list(values), pa.list_(pa.float32()))  # v2.1 parquet: list<float> as HF datasets writes


def _features(
    eps: list[SourceEpisode], names: dict[str, Any], fps: int, codec: str = "h264"
) -> dict[str, dict[str, Any]]:
    first = eps[0]
    feats: dict[str, dict[str, Any]] = {}
    for key, frames in first.images.items():
        h, w = frames.shape[1:3]
        feats[key] = {
            "dtype": "image" if key in first.image_keys else "video",
            "shape": [h, w, 3],
            "names": ["height", "width", "channels"],
            "info": {"video.fps": fps, "video.codec": codec, "video.pix_fmt": "yuv420p"},
        }
    for key, arr in (("observation.state", first.state), ("action", first.action)):
        feats[key] = {"dtype": "float32", "shape": [arr.shape[1]], "names": names.get(key)}
    for key in ("timestamp", "frame_index", "episode_index", "index", "task_index"):
        feats[key] = {"dtype": "float32" if key == "timestamp" else "int64", "shape": [1], "names": None}
    return feats


def write_v21(
    root: Path,
    eps: list[SourceEpisode],
    tasks: list[str],
    *,
    fps: int = 10,
    names: dict[str, Any] | None = None,
    version: str = "v2.1",
) -> Path:
    """A LeRobot v2.1 folder: one parquet and one lossless mp4 per camera per episode."""
    (root / "meta").mkdir(parents=True)
    info = {
        "codebase_version": version,
        "robot_type": "test_bot",
        "total_episodes": len(eps),
        "total_frames": sum(e.length for e in eps),
        "total_tasks": len(tasks),
        "total_chunks": 1,
        "chunks_size": 1000,
        "fps": fps,
        "splits": {"train": f"0:{len(eps)}"},
        "data_path": "data/chunk-{episode_chunk:03d}/episode_{episode_index:06d}.parquet",
        "video_path": "videos/chunk-{episode_chunk:03d}/{video_key}/episode_{episode_index:06d}.mp4",
        "features": _features(eps, names or {}, fps),
    }
    (root / "meta/info.json").write_text(json.dumps(info, indent=2))
    lines = [json.dumps({"task_index": i, "task": t}) for i, t in enumerate(tasks)]
    (root / "meta/tasks.jsonl").write_text("\n".join(lines) + "\n")
    lines = [
        json.dumps({"episode_index": k, "tasks": [tasks[i] for i in dict.fromkeys(e.task_indices)], "length": e.length})
        for k, e in enumerate(eps)
    ]
    (root / "meta/episodes.jsonl").write_text("\n".join(lines) + "\n")
    first = 0
    for k, e in enumerate(eps):
        T = e.length
        cols: dict[str, Any] = {
            "observation.state": _vector(e.state),
            "action": _vector(e.action),
            "timestamp": pa.array(np.arange(T, dtype=np.float32) / fps),
            "frame_index": pa.array(np.arange(T)),
            "episode_index": pa.array(np.full(T, k)),
            "index": pa.array(np.arange(first, first + T)),
            "task_index": pa.array(np.asarray(e.task_indices, dtype=np.int64)),
        }
        for key, frames in e.images.items():
            if key in e.image_keys:  # HF datasets Image(): struct<bytes, path>, PNG of the RGB frame
                pngs = [cv2.imencode(".png", np.ascontiguousarray(f[..., ::-1]))[1].tobytes() for f in frames]
                cols[key] = pa.array([{"bytes": b, "path": None} for b in pngs])
            else:
                video = root / f"videos/chunk-000/{key}/episode_{k:06d}.mp4"
                video.parent.mkdir(parents=True, exist_ok=True)
                encode_video(frames, video, fps, mode="lossless")
        data = root / f"data/chunk-000/episode_{k:06d}.parquet"
        data.parent.mkdir(parents=True, exist_ok=True)
        pq.write_table(pa.table(cols), data)
        first += T
    return root


def write_v30_packed(root: Path, eps: list[SourceEpisode], tasks: list[str], *, fps: int = 10) -> Path:
    """A packed LeRobot v3.0 folder: every episode in ONE data parquet and ONE mp4 per camera."""
    (root / "meta").mkdir(parents=True)
    lengths = [e.length for e in eps]
    starts = np.concatenate([[0], np.cumsum(lengths)]).astype(int)
    data = root / "data/chunk-000/file-000.parquet"
    data.parent.mkdir(parents=True)
    pq.write_table(
        pa.table(
            {
                "observation.state": _vector(np.concatenate([e.state for e in eps])),
                "action": _vector(np.concatenate([e.action for e in eps])),
                "timestamp": pa.array(np.concatenate([np.arange(T, dtype=np.float32) / fps for T in lengths])),
                "frame_index": pa.array(np.concatenate([np.arange(T) for T in lengths])),
                "episode_index": pa.array(np.concatenate([np.full(T, k) for k, T in enumerate(lengths)])),
                "index": pa.array(np.arange(starts[-1])),
                "task_index": pa.array(np.concatenate([np.asarray(e.task_indices) for e in eps]).astype(np.int64)),
            }
        ),
        data,
    )
    rows: list[dict[str, Any]] = [
        {
            "episode_index": k,
            "tasks": [tasks[e.task_indices[0]]],
            "length": e.length,
            "data/chunk_index": 0,
            "data/file_index": 0,
            "dataset_from_index": int(starts[k]),
            "dataset_to_index": int(starts[k + 1]),
            "meta/episodes/chunk_index": 0,
            "meta/episodes/file_index": 0,
        }
        for k, e in enumerate(eps)
    ]
    for key in eps[0].images:
        video = root / f"videos/{key}/chunk-000/file-000.mp4"
        video.parent.mkdir(parents=True)
        encode_video(np.concatenate([e.images[key] for e in eps]), video, fps, mode="lossless")
        for k, row in enumerate(rows):  # episode k spans [from, to) seconds of the shared file
            row.update(
                {
                    f"videos/{key}/chunk_index": 0,
                    f"videos/{key}/file_index": 0,
                    f"videos/{key}/from_timestamp": float(starts[k]) / fps,
                    f"videos/{key}/to_timestamp": float(starts[k + 1]) / fps,
                }
            )
    meta = root / "meta/episodes/chunk-000/file-000.parquet"
    meta.parent.mkdir(parents=True)
    pq.write_table(pa.Table.from_pylist(rows), meta)
    pq.write_table(
        pa.table({"task_index": pa.array(range(len(tasks)), pa.int64()), "task": tasks}), root / "meta/tasks.parquet"
    )
    info = {
        "codebase_version": "v3.0",
        "robot_type": "test_bot",
        "total_episodes": len(eps),
        "total_frames": int(starts[-1]),
        "total_tasks": len(tasks),
        "chunks_size": 1000,
        "data_files_size_in_mb": 100,
        "video_files_size_in_mb": 200,
        "fps": fps,
        "splits": {"train": f"0:{len(eps)}"},
        "data_path": "data/chunk-{chunk_index:03d}/file-{file_index:03d}.parquet",
        "video_path": "videos/{video_key}/chunk-{chunk_index:03d}/file-{file_index:03d}.mp4",
        "features": _features(eps, {}, fps),
    }
    (root / "meta/info.json").write_text(json.dumps(info, indent=2))
    return root


@dataclass
class AlohaEpisode:
    images: dict[str, NDArray[np.uint8]]
    qpos: NDArray[np.float32]
    action: NDArray[np.float32]
    jpegs: dict[str, list[NDArray[np.uint8]]] = field(default_factory=dict)  # what the file holds, if compressed


ALOHA_CAMS = ("cam_high", "cam_low", "cam_left_wrist", "cam_right_wrist")


def write_aloha(
    path: Path,
    T: int,
    seed: int,
    *,
    compress: bool = False,
    cams: tuple[str, ...] = ALOHA_CAMS,
    size: tuple[int, int] = (32, 32),
) -> AlohaEpisode:
    """One ALOHA episode file, raw (record_sim_episodes.py) or JPEG-compressed (act-plus-plus)."""
    rng = np.random.default_rng(seed)
    h, w = size
    make = smooth_frames if compress else noise_frames
    ep = AlohaEpisode(
        images={cam: make(T, h, w, seed=seed * 10 + i) for i, cam in enumerate(cams)},
        qpos=rng.standard_normal((T, 14)).astype(np.float32),
        action=rng.standard_normal((T, 14)).astype(np.float32),
    )
    path.parent.mkdir(parents=True, exist_ok=True)
    with h5py.File(path, "w") as root:
        root.attrs["sim"] = False
        obs = root.create_group("observations")
        images = obs.create_group("images")
        obs.create_dataset("qpos", data=ep.qpos)
        obs.create_dataset("qvel", data=np.zeros((T, 14), np.float32))
        root.create_dataset("action", data=ep.action)
        if not compress:
            for cam, frames in ep.images.items():
                images.create_dataset(cam, data=frames, chunks=(1, h, w, 3))
            return ep
        root.attrs["compress"] = True
        lens = []
        for cam in sorted(cams):  # h5py lists a group's members by name: compress_len rows follow that order
            # As ALOHA does: cv2.imencode on the RGB array as it is (OpenCV takes it for BGR).
            enc = [cv2.imencode(".jpg", f, [int(cv2.IMWRITE_JPEG_QUALITY), 90])[1].reshape(-1) for f in ep.images[cam]]
            ep.jpegs[cam] = enc
            lens.append([len(e) for e in enc])
            padded = np.zeros((T, max(lens[-1]) + 7), np.uint8)  # zero padding after each image, as ALOHA pads
            for t, e in enumerate(enc):
                padded[t, : len(e)] = e
            images.create_dataset(cam, data=padded)
        root.create_dataset("compress_len", data=np.asarray(lens, dtype=np.float32))
    return ep
