"""Frame helpers shared by the importers: video sizes, embedded PNG/JPEG images (decoding: video_codec).

Sources such as RealSource World hold 720×1280 cameras: a 1000-frame episode is 2.7 GB per camera
at full size. Decoding into a list and resizing afterwards would hold all of it; here every frame is
resized as soon as it is decoded, into one preallocated array of the output size.
"""

from __future__ import annotations

from pathlib import Path

import av
import cv2
import numpy as np
from numpy.typing import NDArray

from pilworld.data.video_codec import resize_image


def video_size(path: Path) -> tuple[int, int]:
    """(height, width) of the first video stream of ``path``."""
    if not path.is_file():
        raise ValueError(f"{path}: video file missing")
    with av.open(str(path)) as container:
        stream = container.streams.video[0]
        return int(stream.codec_context.height), int(stream.codec_context.width)


def decode_encoded_image(data: bytes | NDArray[np.uint8], *, where: str) -> NDArray[np.uint8]:
    """A PNG/JPEG file in memory → the array OpenCV decodes (channel order as stored: see callers)."""
    buf = np.frombuffer(data, dtype=np.uint8) if isinstance(data, bytes) else data
    image = cv2.imdecode(buf, cv2.IMREAD_COLOR)
    if image is None:
        raise ValueError(f"{where}: not a decodable image ({len(buf)} bytes)")
    return np.asarray(image, dtype=np.uint8)


def read_image_column(cells: list[object], *, size: tuple[int, int], resize: bool, where: str) -> NDArray[np.uint8]:
    """RGB frames (T, H, W, 3) from a LeRobot ``image`` column (``{"bytes": PNG, "path": ...}`` per row).

    The files are real PNG/JPEG images (written by PIL from RGB), which OpenCV decodes as BGR, so the
    channels are swapped back here. Without ``resize``, a frame not of ``size`` is an error.
    """
    out = np.empty((len(cells), *size, 3), dtype=np.uint8)
    for t, cell in enumerate(cells):
        data = cell.get("bytes") if isinstance(cell, dict) else None
        if not isinstance(data, bytes):
            raise ValueError(f"{where}: row {t} holds no embedded image bytes (image files by path are not supported)")
        image = decode_encoded_image(data, where=f"{where}: row {t}")[..., ::-1]
        if not resize and image.shape[:2] != size:
            raise ValueError(f"{where}: row {t} is {image.shape[:2]}, expected {size}")
        out[t] = resize_image(np.ascontiguousarray(image), size)
    return out
