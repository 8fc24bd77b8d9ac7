"""Importer for ALOHA HDF5 episodes (tonyzhaozh/act, MarkFzp/act-plus-plus, the ALOHA recorders).

One file per episode, ``episode_0.hdf5``, ``episode_1.hdf5``, … (ordered by number, so 10 follows 9)::

    /observations/qpos            (T, 14)  joint positions: left arm 6 + gripper, right arm 6 + gripper
    /observations/qvel            (T, 14)
    /observations/images/<cam>    (T, H, W, 3) uint8 — or (T, N) uint8: JPEG bytes padded with zeros
    /action                       (T, 14)
    /compress_len                 (cams, T) true byte length of each JPEG (compressed files only)
    attrs: sim (bool), compress (bool, compressed files only)

Colour: the recorders store RGB arrays (MuJoCo renders, ROS rgb8 images; ALOHA's own viewers swap
to BGR only before ``cv2.VideoWriter``). Compressed files come from ``cv2.imencode('.jpg', rgb)``
applied to those RGB arrays as they are: OpenCV takes them for BGR, and ``cv2.imdecode`` hands back
the very same channel order, i.e. RGB again. So no conversion is applied (a BGR→RGB conversion, as
some converters do, would swap red and blue relative to the raw files of the same recorder); set
``color_order: bgr`` in the mapping for a recorder that stored BGR arrays.

There is no instruction in the files: the mapping's ``task`` (or ``--task``) is required. The rate is
not stored either: 50 fps (ACT's ``DT = 0.02``) unless the mapping sets ``fps``.
"""

from __future__ import annotations

import re
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import h5py
import numpy as np
from numpy.typing import NDArray

from pilworld.data.convert.base import EpisodeSource, feature_names, provenance_entry
from pilworld.data.convert.frames import decode_encoded_image
from pilworld.data.convert.mapping import ConvertMapping
from pilworld.data.episode import Episode
from pilworld.data.video_codec import resize_image

ALOHA_FPS = 50
IMAGES = "/observations/images"
STATE = "/observations/qpos"
ACTION = "/action"
COMPRESS_LEN = "/compress_len"
_JOINTS = ("waist", "shoulder", "elbow", "forearm_roll", "wrist_angle", "wrist_rotate", "gripper")
ALOHA_NAMES = tuple(f"{side}_{joint}" for side in ("left", "right") for joint in _JOINTS)  # LeRobot's aloha names
_BLOCK = 64  # raw frames read from HDF5 at a time (bounded memory before resizing)


def episode_files(path: Path) -> list[Path]:
    """The episode files of ``path`` (one file, or a folder), in numeric order."""
    if path.is_file():
        return [path]
    if not path.is_dir():
        raise ValueError(f"{path}: no such file or folder")
    files = list(path.glob("episode_*.hdf5")) or [*path.glob("*.hdf5"), *path.glob("*.h5")]
    if not files:
        raise ValueError(f"{path}: no .hdf5 episode files")

    def key(p: Path) -> tuple[int, str]:
        numbers = re.findall(r"\d+", p.stem)
        return (int(numbers[-1]) if numbers else -1, p.name)

    return sorted(files, key=key)


def _dataset(f: h5py.File, key: str, role: str, *, where: Path) -> h5py.Dataset:
    obj = f.get(key)
    if not isinstance(obj, h5py.Dataset):
        found: list[str] = []
        f.visititems(lambda name, o: found.append("/" + name) if isinstance(o, h5py.Dataset) else None)
        raise ValueError(f"{where}: no dataset {key!r} for the {role} (datasets: {sorted(found)}); set '{role}_key'")
    return obj


def _cameras(f: h5py.File, *, where: Path) -> dict[str, h5py.Dataset]:
    """RGB cameras of a file: raw (T, H, W, 3) or JPEG (T, N) uint8 datasets (depth maps are skipped)."""
    group = f.get(IMAGES)
    if not isinstance(group, h5py.Group):
        raise ValueError(f"{where}: no {IMAGES} group")
    cams = {}
    for name, obj in group.items():
        raw = isinstance(obj, h5py.Dataset) and obj.ndim == 4 and obj.shape[-1] == 3
        jpeg = isinstance(obj, h5py.Dataset) and obj.ndim == 2
        if (raw or jpeg) and obj.dtype == np.uint8:
            cams[name] = obj
    return cams


class AlohaHdf5Source(EpisodeSource):
    """A folder of ALOHA HDF5 episodes (or one file), read one episode at a time."""

    format_name = "aloha-hdf5"

    def __init__(self, path: Path, mapping: ConvertMapping) -> None:
        super().__init__(path, mapping)
        self.files = episode_files(self.path)
        self.task = self.fallback_task(str(self.path))  # fail before any output is created
        self.fps = mapping.fps or ALOHA_FPS
        self.robot_type = mapping.robot_type or "aloha"
        self.state_key = "/" + (mapping.state_key or STATE).lstrip("/")
        self.action_key = "/" + (mapping.action_key or ACTION).lstrip("/")
        first = self.files[0]
        with h5py.File(first, "r") as f:
            cams = _cameras(f, where=first)
            self.cameras = self.mapping.select_cameras(list(cams), source=f"{first}:{IMAGES}")
            self.views = {}
            for name, view in self.cameras.items():
                self.views[view] = self.output_size(self._frame_size(cams[name], where=f"{first}: camera {name!r}"))
            names: dict[str, tuple[str, ...]] = {}
            for role, key in (("state", self.state_key), ("action", self.action_key)):
                ds = _dataset(f, key, role, where=first)
                if ds.ndim != 2:
                    raise ValueError(f"{first}: {key!r} has shape {ds.shape}; expected (T, dims)")
                width = int(ds.shape[1])
                given = ds.attrs.get("names")
                given = [x.decode() if isinstance(x, bytes) else str(x) for x in given] if given is not None else None
                names[role] = feature_names(given or (ALOHA_NAMES if width == 14 else None), width, role)
        self.state_names, self.action_names = names["state"], names["action"]
        self._lengths: list[int] | None = None

    def lengths(self) -> list[int]:
        if self._lengths is None:  # one metadata read per file, no frames
            lengths = []
            for file in self.files:
                with h5py.File(file, "r") as f:
                    lengths.append(int(_dataset(f, self.action_key, "action", where=file).shape[0]))
            self._lengths = lengths
        return self._lengths

    def provenance(self, position: int) -> dict[str, Any]:
        return provenance_entry(self.format_name, position, self.files[position].name)

    def iter_episodes(self, start: int = 0) -> Iterator[Episode]:
        for position in range(start, len(self.files)):
            yield self._load(position)

    def _frame_size(self, ds: h5py.Dataset, *, where: str) -> tuple[int, int]:
        """(height, width) of a camera's frames (a JPEG camera's first frame is decoded to find out)."""
        if ds.ndim == 4:
            return int(ds.shape[1]), int(ds.shape[2])
        if ds.shape[0] == 0:
            raise ValueError(f"{where}: no frames")
        h, w = self._decode(ds[0], where=f"{where} frame 0").shape[:2]
        return int(h), int(w)

    def _decode(self, buf: NDArray[np.uint8], *, where: str) -> NDArray[np.uint8]:
        """One JPEG frame (zero padding after the image is ignored by the decoder) in the stored order."""
        return decode_encoded_image(np.ascontiguousarray(buf), where=where)

    def _load(self, position: int) -> Episode:
        file = self.files[position]
        with h5py.File(file, "r") as f:
            action = np.asarray(_dataset(f, self.action_key, "action", where=file)[()], dtype=np.float32)
            state = np.asarray(_dataset(f, self.state_key, "state", where=file)[()], dtype=np.float32)
            T = action.shape[0]
            if state.shape[0] != T:
                raise ValueError(f"{file}: {self.state_key} has {state.shape[0]} rows but {self.action_key} has {T}")
            for role, arr, width in (
                ("state", state, len(self.state_names)),
                ("action", action, len(self.action_names)),
            ):
                if arr.ndim != 2 or arr.shape[1] != width:
                    raise ValueError(f"{file}: {role} has shape {arr.shape}; the first file had {width} dims")
            cams = _cameras(f, where=file)
            lens = f.get(COMPRESS_LEN)
            compress_len = np.asarray(lens[()]) if isinstance(lens, h5py.Dataset) else None
            jpeg_rows = [name for name, ds in cams.items() if ds.ndim == 2]  # row order of compress_len
            images: dict[str, NDArray[np.uint8]] = {}
            for name, view in self.cameras.items():
                if name not in cams:
                    raise ValueError(f"{file}: camera {name!r} missing (available: {sorted(cams)})")
                ds = cams[name]
                if ds.shape[0] != T:
                    raise ValueError(f"{file}: camera {name!r} has {ds.shape[0]} frames but {self.action_key} has {T}")
                row = None
                if ds.ndim == 2 and compress_len is not None and compress_len.shape == (len(jpeg_rows), T):
                    row = compress_len[jpeg_rows.index(name)]
                images[view] = self._frames(ds, view, row, where=f"{file}: camera {name!r}")
        return Episode(
            images=images,
            state=state,
            action=action,
            task=self.task,
            origin=self.mapping.origin or "real",
            extra=self.provenance(position),
        )

    def _frames(self, ds: h5py.Dataset, view: str, lengths: Any, *, where: str) -> NDArray[np.uint8]:
        """All frames of one camera at the output size, read in blocks."""
        T = int(ds.shape[0])
        size = self.views[view]
        out = np.empty((T, *size, 3), dtype=np.uint8)
        for s in range(0, T, _BLOCK):
            block = ds[s : s + _BLOCK]
            for i, item in enumerate(block):
                t = s + i
                if ds.ndim == 4:
                    image = np.asarray(item, dtype=np.uint8)
                else:
                    buf = np.asarray(item, dtype=np.uint8)
                    n = int(lengths[t]) if lengths is not None else 0
                    # Trust /compress_len only where it ends on the JPEG end-of-image marker (FF D9):
                    # its row order is not recorded in the file; the decoder ignores the padding anyway.
                    if 2 <= n <= buf.size and buf[n - 2] == 0xFF and buf[n - 1] == 0xD9:
                        buf = buf[:n]
                    image = self._decode(buf, where=f"{where} frame {t}")
                if self.mapping.color_order == "bgr":
                    image = np.ascontiguousarray(image[..., ::-1])  # BGR → RGB
                if self.mapping.resize is None and image.shape[:2] != size:
                    raise ValueError(f"{where}: frame {t} is {image.shape[:2]}, the first file's is {size}")
                out[t] = resize_image(image, size)
        return out
