"""The head camera's empty scene: a robot-masked per-pixel median over many recorded frames.

A static camera sees the same table and background in every episode; only the objects (placed at random)
and the robot move. The per-pixel median of many frames, each with the robot's pixels (from its render at
the recorded state, slightly dilated) left out, is therefore the empty scene: what a pixel shows once an
arm or a carried object has left it, when no current frame can say.
"""

from __future__ import annotations

import cv2
import numpy as np
from numpy.typing import NDArray
from tqdm import tqdm

from pilworld.types import HEAD_VIEW


def estimate_plate(
    data: str, rig: object, *, frames: int = 240, seed: int = 0, progress: bool = True
) -> NDArray[np.float32]:
    """(3, H, W) float32 in [0, 1]: the empty head-camera scene of dataset ``data`` recorded on ``rig``."""
    from pilworld.control_video.robot_render import make_robot_renderer
    from pilworld.data.clip_dataset import ClipDataset

    ds = ClipDataset(data)
    if HEAD_VIEW not in ds.views:
        raise ValueError(f"{data}: no {HEAD_VIEW!r} view to estimate the empty scene from")
    head = ds.views.index(HEAD_VIEW)
    renderer = make_robot_renderer(rig, "analytic")  # type: ignore[arg-type]
    rng = np.random.default_rng(seed)
    picks = np.sort(rng.choice(len(ds), min(frames, len(ds)), replace=False))
    stack = []
    kernel = np.ones((5, 5), np.uint8)
    for i in tqdm(picks, desc="empty scene", unit="frame", disable=not progress):
        item = ds[int(i)]
        img = np.moveaxis(item["current"][head].numpy(), 0, -1).astype(np.float32) / 255.0
        q = item["state"].numpy().astype(np.float64)[None]
        parts = renderer.render(q, depth=False, shaded=False).parts[HEAD_VIEW][0]
        robot = cv2.dilate((parts > 0).astype(np.uint8), kernel) > 0
        img[robot] = np.nan
        stack.append(img)
    plate = np.nanmedian(np.stack(stack), axis=0)
    plate = np.where(np.isnan(plate), np.nanmedian(plate, axis=(0, 1)), plate)  # never free of robot: the mean colour
    return np.ascontiguousarray(plate.transpose(2, 0, 1)).astype(np.float32)
