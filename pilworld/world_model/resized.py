"""A world model run at another image size than the rig's (the speed-versus-accuracy sweep).

A model trained at, say, 32×32 can drive the imagined branch of a 128×128 rig: its inputs — current
and history frames, the control video Γ — are area-resized down to the model's size, and its
predictions are resized back up (bilinear) so judges, metrics and reports see the rig's size. The
figures then say what the small model's frames are worth at the resolution the judges work at.
"""

from __future__ import annotations

import dataclasses

import numpy as np
import torch
from numpy.typing import NDArray

from pilworld.world_model.base import PredictRequest, WorldModel, WorldModelBatch, WorldModelInfo, predict_one
from pilworld.world_model.batching import resize_images


def upsample_images(x: torch.Tensor, height: int, width: int) -> torch.Tensor:
    """Bilinear-resize uint8 images [..., 3, h, w] to [..., 3, height, width] (uint8)."""
    if tuple(x.shape[-2:]) == (height, width):
        return x
    lead = x.shape[:-3]
    flat = x.reshape(-1, *x.shape[-3:]).float()
    out = torch.nn.functional.interpolate(flat, size=(height, width), mode="bilinear", align_corners=False)
    return out.round().clamp(0, 255).to(torch.uint8).reshape(*lead, 3, height, width)


class ResizedWorldModel:
    """``model`` seen at ``height × width``: inputs resized to the model's size, predictions back."""

    def __init__(self, model: WorldModel, height: int, width: int) -> None:
        if height < 1 or width < 1:
            raise ValueError(f"size: expected positive height and width, got {height}x{width}")
        self.model = model
        self._info = dataclasses.replace(model.info, height=height, width=width)

    @property
    def info(self) -> WorldModelInfo:
        return self._info

    @property
    def native_size(self) -> tuple[int, int]:
        """(width, height) the wrapped model works at."""
        return self.model.info.width, self.model.info.height

    def predict_batch(self, batch: WorldModelBatch, *, steps: int | None = None, seed: int = 0) -> torch.Tensor:
        batch.check(self._info)
        h, w = self.model.info.height, self.model.info.width
        small = WorldModelBatch(
            current=resize_images(batch.current, h, w),
            history=resize_images(batch.history, h, w),
            history_valid=batch.history_valid,
            control=resize_images(batch.control, h, w),
            actions=batch.actions,
            instruction=list(batch.instruction),
        )
        out = self.model.predict_batch(small, steps=steps, seed=seed)
        return upsample_images(out, self._info.height, self._info.width)

    def predict(
        self, request: PredictRequest, *, steps: int | None = None, seed: int = 0
    ) -> dict[str, NDArray[np.uint8]]:
        return predict_one(self, request, steps=steps, seed=seed)
