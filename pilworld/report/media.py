"""Frames for the report: the per-pair tile video, its poster, the control video Γ rebuilt per round.

A pair's tile stacks one row per camera view plus a row for Γ, with the real branch in the left column
and the imagined branch in the right one, so the two branches play frame-locked in one ``<video>``.
The tile is encoded as browser-playable H.264 (yuv420p, ``pilworld.io.video.write_mp4``) and embedded as
a ``data:`` URI; the poster is a PNG of the last frame (where the branches differ most).
"""

from __future__ import annotations

import base64
import tempfile
from pathlib import Path

import cv2
import numpy as np
from numpy.typing import NDArray

from pilworld.control_video.gamma import ControlVideo
from pilworld.data.episode import Episode
from pilworld.io.video import write_mp4
from pilworld.types import STATE_DIM

VIEW_ORDER = ("cam_high", "cam_left_wrist", "cam_right_wrist")  # head first, then left, right
GAP = 4  # px between tiles (even, so the tile keeps even sizes for 4:2:0 chroma)
GAP_GREY = 48
CONTROL_ROW = "control video Γ"


def ordered_views(views: list[str]) -> list[str]:
    """The known views in head, left, right order, then any others alphabetically."""
    known = [v for v in VIEW_ORDER if v in views]
    return known + sorted(v for v in views if v not in VIEW_ORDER)


def _fit(frames: NDArray[np.uint8], length: int, size: tuple[int, int]) -> NDArray[np.uint8]:
    """``frames`` (T, h, w, 3) resized to ``size`` (h, w) and padded to ``length`` by repeating the last frame."""
    h, w = size
    if frames.shape[1:3] != (h, w):
        frames = np.stack([cv2.resize(f, (w, h), interpolation=cv2.INTER_AREA) for f in frames])
    if frames.shape[0] < length:
        frames = np.concatenate([frames, np.repeat(frames[-1:], length - frames.shape[0], axis=0)])
    return frames[:length]


def control_frames(episode: Episode, gamma: ControlVideo | None) -> NDArray[np.uint8]:
    """Γ of an episode as it was fed to the world model, one control frame per stored frame (T, H, W, 3).

    Round ``r``'s frames are the frames with ``round_index == r`` after the start frame; the control frame
    of frame ``j`` is drawn at the stride-aligned command stored with frame ``j − 1`` (the command whose
    effect frame ``j`` shows), with the state at the round's start frame as the previous state. The start
    frame has no control frame (black), and so does any round that does not have exactly K frames.
    """
    T = episode.length
    if gamma is None:
        return np.zeros((T, 1, 1, 3), dtype=np.uint8)
    out = np.zeros((T, gamma.height, gamma.width, 3), dtype=np.uint8)
    if episode.action.shape[1] != STATE_DIM or episode.state.shape[1] != STATE_DIM:
        return out
    K = gamma.spec.frames
    rounds = episode.rounds()
    frames_of: list[NDArray[np.intp]] = []
    for r in np.unique(rounds[1:]):
        idx = np.nonzero(rounds == r)[0]
        idx = idx[idx > 0]
        if len(idx) == K and np.all(np.diff(idx) == 1):
            frames_of.append(idx)
    if not frames_of:
        return out
    stride = np.stack([episode.action[idx - 1] for idx in frames_of]).astype(np.float64)  # (R, K, 14)
    previous = np.stack([episode.state[idx[0] - 1] for idx in frames_of]).astype(np.float64)  # (R, 14)
    rendered = gamma.render_stride_aligned(stride, previous)  # (R, K, H, W, 3)
    for idx, frames in zip(frames_of, rendered, strict=True):
        out[idx] = frames
    return out


def tile(
    branches: dict[str, dict[str, NDArray[np.uint8]]],
    columns: tuple[str, ...],
    rows: list[str],
    size: tuple[int, int],
) -> NDArray[np.uint8]:
    """Frames (T, rows·h + gaps, columns·w + gaps, 3): ``branches[column][row]`` placed in the grid.

    A missing (column, row) stays dark grey; all cells are padded to the longest branch.
    """
    h, w = size
    length = max((f.shape[0] for b in branches.values() for f in b.values()), default=1)
    H = len(rows) * h + (len(rows) - 1) * GAP
    W = len(columns) * w + (len(columns) - 1) * GAP
    out = np.full((length, H, W, 3), GAP_GREY, dtype=np.uint8)
    for c, column in enumerate(columns):
        for r, row in enumerate(rows):
            frames = branches.get(column, {}).get(row)
            if frames is None or frames.shape[0] == 0:
                continue
            y, x = r * (h + GAP), c * (w + GAP)
            out[:, y : y + h, x : x + w] = _fit(frames, length, size)
    return out


def mp4_bytes(frames: NDArray[np.uint8], fps: float, crf: int) -> bytes:
    """H.264 MP4 (yuv420p) of RGB frames (T, H, W, 3), in memory."""
    with tempfile.TemporaryDirectory(prefix="pilworld-report-") as tmp:
        path = write_mp4(frames, Path(tmp) / "tile.mp4", fps=fps, crf=crf)
        return path.read_bytes()


def png_bytes(image: NDArray[np.uint8]) -> bytes:
    """Lossless PNG of one RGB image (H, W, 3)."""
    ok, buf = cv2.imencode(".png", cv2.cvtColor(image, cv2.COLOR_RGB2BGR), [cv2.IMWRITE_PNG_COMPRESSION, 9])
    if not ok:
        raise OSError("PNG encoding failed")
    return bytes(buf.tobytes())


def data_uri(mime: str, payload: bytes) -> str:
    return f"data:{mime};base64,{base64.b64encode(payload).decode('ascii')}"


def frame_mse(a: NDArray[np.uint8], b: NDArray[np.uint8]) -> NDArray[np.float64]:
    """Per-frame mean squared error (levels²) of two frame stacks (T, H, W, 3) over their common length."""
    n = min(a.shape[0], b.shape[0])
    if a.shape[1:] != b.shape[1:]:
        return np.full(n, np.nan)
    d = a[:n].astype(np.float64) - b[:n].astype(np.float64)
    mse: NDArray[np.float64] = np.mean(d * d, axis=(1, 2, 3))
    return mse


def psnr_of_mse(mse: NDArray[np.float64], data_range: float = 255.0) -> NDArray[np.float64]:
    """PSNR in dB of a mean squared error; inf where the error is 0."""
    with np.errstate(divide="ignore"):
        out: NDArray[np.float64] = 10.0 * np.log10(data_range**2 / mse)
    return out
