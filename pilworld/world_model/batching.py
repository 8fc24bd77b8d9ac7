"""Training clips → :class:`WorldModelBatch`: stacking, and the head-view control video Γ for each clip.

A clip stores its stride-aligned actions and the state at its current frame; Γ draws the control
video from exactly those (the state gives the trace segment into frame 0), as the imagined branch
does at rollout time with the policy-side state. So training and rollout see the same control frames.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np
import torch

from pilworld.config.rig import RigConfig
from pilworld.control_video.gamma import ControlVideo
from pilworld.types import ChunkSpec
from pilworld.world_model.base import WorldModelBatch, WorldModelInfo


def control_renderer(rig: RigConfig, info: WorldModelInfo, stride: int = 3) -> ControlVideo:
    """Γ for ``rig`` at the model's image size and K (the head camera resized to it)."""
    camera = rig.head_camera_model
    if (camera.width, camera.height) != (info.width, info.height):
        camera = camera.resized(info.width, info.height)
    spec = ChunkSpec(horizon=max(50, info.future * stride), frames=info.future, stride=stride)
    return ControlVideo(rig.kinematics, camera, spec)


def collate_clips(items: Sequence[dict[str, Any]], gamma: ControlVideo) -> WorldModelBatch:
    """Stack :class:`~pilworld.data.clip_dataset.ClipDataset` items and draw their control videos."""
    if not items:
        raise ValueError("collate_clips: no items")
    actions = torch.stack([it["actions"] for it in items]).float()  # [B, K, 14]
    states = torch.stack([it["state"] for it in items]).double().numpy()  # [B, 14]
    control = gamma.render_stride_aligned(actions.double().numpy(), states)  # [B, K, H, W, 3]
    return WorldModelBatch(
        current=torch.stack([it["current"] for it in items]),
        history=torch.stack([it["history"] for it in items]),
        history_valid=torch.stack([it["history_valid"] for it in items]),
        control=torch.from_numpy(np.ascontiguousarray(np.moveaxis(control, -1, -3))),
        actions=actions,
        instruction=[str(it["instruction"]) for it in items],
        future=torch.stack([it["future"] for it in items]),
        state=torch.stack([torch.as_tensor(it["state"]) for it in items])
        if all("state" in it for it in items)
        else None,
    )


def resize_images(x: torch.Tensor, height: int, width: int) -> torch.Tensor:
    """Area-resize uint8 images [..., 3, h, w] to [..., 3, height, width] (uint8)."""
    if tuple(x.shape[-2:]) == (height, width):
        return x
    lead = x.shape[:-3]
    flat = x.reshape(-1, *x.shape[-3:]).float()
    out = torch.nn.functional.interpolate(flat, size=(height, width), mode="area")
    return out.round().clamp(0, 255).to(torch.uint8).reshape(*lead, 3, height, width)
