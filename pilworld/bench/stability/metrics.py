"""Frame errors with the world-model metrics' definitions (PSNR capped for identical frames)."""

from __future__ import annotations

import numpy as np
import torch
from numpy.typing import NDArray

from pilworld.world_model.metrics import mse, psnr_from_mse


def _chw(a: NDArray[np.uint8]) -> torch.Tensor:
    """A decoded [..., H, W, 3] frame as the channels-first tensor the world-model metrics take."""
    return torch.from_numpy(np.ascontiguousarray(np.moveaxis(a, -1, -3)))


def frame_psnr(a: NDArray[np.uint8], b: NDArray[np.uint8]) -> float:
    """Whole-frame PSNR (dB) with the world-model metrics' definition and cap (identical frames)."""
    return float(psnr_from_mse(mse(_chw(a), _chw(b)).mean()))


def frame_mse(a: NDArray[np.uint8], b: NDArray[np.uint8]) -> float:
    return float(mse(_chw(a), _chw(b)).mean())
