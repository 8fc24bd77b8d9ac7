"""Write frame stacks as MP4 (PyAV, H.264) or as a PNG contact sheet (OpenCV).

MP4 is for looking at; H.264 with 4:2:0 chroma is lossy, so never compute image metrics on it (the
episode store has a lossless mode for that). The PNG sheet is lossless and handy in reports and issues.
"""

from __future__ import annotations

from fractions import Fraction
from pathlib import Path

import av
import cv2
import numpy as np
from numpy.typing import NDArray

VIDEO_SUFFIXES = (".mp4",)
IMAGE_SUFFIXES = (".png",)


def _check_frames(frames: NDArray[np.uint8]) -> None:
    if frames.dtype != np.uint8 or frames.ndim != 4 or frames.shape[-1] != 3 or frames.shape[0] == 0:
        raise ValueError(f"frames: expected uint8 (N, H, W, 3) with N > 0, got {frames.dtype} {frames.shape}")


def write_mp4(
    frames: NDArray[np.uint8],
    path: str | Path,
    fps: float = 10.0,
    crf: int = 18,
    *,
    keyframe_every: int | None = None,
    bitexact: bool = False,
) -> Path:
    """Encode RGB frames (N, H, W, 3) as H.264 (yuv420p; odd sizes are padded by one black pixel).

    ``keyframe_every``: the GOP length (short GOPs make seeking cheap; default: the encoder's).
    ``bitexact``: no muxer version tag in the container.
    """
    _check_frames(frames)
    if not fps > 0:
        raise ValueError(f"fps: expected a positive frame rate, got {fps!r}")
    from pilworld.io.run_folder import check_path_text

    check_path_text(path, "out")
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    n, h, w, _ = frames.shape
    # 4:2:0 chroma needs even sizes; pad rather than resize so pixels keep their coordinates.
    pad_h, pad_w = h % 2, w % 2
    if pad_h or pad_w:
        frames = np.pad(frames, ((0, 0), (0, pad_h), (0, pad_w), (0, 0)))
    rate = Fraction(fps).limit_denominator(1001)
    with av.open(str(path), mode="w", options={"fflags": "+bitexact"} if bitexact else {}) as container:
        stream = container.add_stream("libx264", rate=rate)
        stream.width, stream.height = w + pad_w, h + pad_h
        stream.pix_fmt = "yuv420p"
        gop = {} if keyframe_every is None else {"g": str(keyframe_every)}
        stream.options = {"crf": str(crf), "preset": "medium", **gop}
        for i in range(n):
            frame = av.VideoFrame.from_ndarray(np.ascontiguousarray(frames[i]), format="rgb24")
            for packet in stream.encode(frame):
                container.mux(packet)
        for packet in stream.encode():
            container.mux(packet)
    return path


def contact_sheet(frames: NDArray[np.uint8], columns: int = 5, gap: int = 2) -> NDArray[np.uint8]:
    """Tile frames (N, H, W, 3) row by row into one image with ``gap`` grey pixels between tiles."""
    _check_frames(frames)
    n, h, w, _ = frames.shape
    columns = max(1, min(columns, n))
    rows = -(-n // columns)
    sheet = np.full((rows * h + (rows - 1) * gap, columns * w + (columns - 1) * gap, 3), 64, np.uint8)
    for i in range(n):
        r, c = divmod(i, columns)
        sheet[r * (h + gap) : r * (h + gap) + h, c * (w + gap) : c * (w + gap) + w] = frames[i]
    return sheet


def write_png(image: NDArray[np.uint8], path: str | Path) -> Path:
    """Write one RGB image (H, W, 3) losslessly."""
    if image.dtype != np.uint8 or image.ndim != 3 or image.shape[-1] != 3:
        raise ValueError(f"image: expected uint8 (H, W, 3), got {image.dtype} {image.shape}")
    from pilworld.io.run_folder import check_path_text

    check_path_text(path, "out")  # OpenCV crashes (SIGSEGV) on a path that is not UTF-8
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    if not cv2.imwrite(str(path), cv2.cvtColor(image, cv2.COLOR_RGB2BGR)):
        raise OSError(f"could not write {path}")
    return path


def write_frames(frames: NDArray[np.uint8], path: str | Path, fps: float = 10.0, columns: int = 5) -> Path:
    """Write by suffix: ``.mp4`` → video, ``.png`` → contact sheet of all frames."""
    path = Path(path)
    suffix = path.suffix.lower()
    if suffix in VIDEO_SUFFIXES:
        return write_mp4(frames, path, fps=fps)
    if suffix in IMAGE_SUFFIXES:
        return write_png(contact_sheet(frames, columns=columns), path)
    raise ValueError(f"out: unsupported file type {path.suffix!r} for {path}; use .mp4 or .png")
