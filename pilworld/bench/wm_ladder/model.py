"""The world model under test, as the rungs need it: its frame autoencoder, seeds shifted per round, one per task."""

from __future__ import annotations

from collections.abc import Callable, Mapping
from pathlib import Path
from typing import Any

import numpy as np
import torch

from pilworld.bench.wm_ladder.settings import Frames, check_model_folder
from pilworld.config.rig import RigConfig
from pilworld.types import ChunkSpec
from pilworld.world_model.base import PredictRequest, WorldModel, WorldModelBatch, WorldModelInfo


class SeedShifted:
    """``model`` with every seed shifted by ``offset``: a teacher-forced round r draws the noise of round r."""

    def __init__(self, model: WorldModel, offset: int) -> None:
        self.model = model
        self.offset = offset

    @property
    def info(self) -> WorldModelInfo:
        return self.model.info

    def predict_batch(self, batch: WorldModelBatch, *, steps: int | None = None, seed: int = 0) -> torch.Tensor:
        return self.model.predict_batch(batch, steps=steps, seed=seed + self.offset)

    def predict(self, request: PredictRequest, *, steps: int | None = None, seed: int = 0) -> dict[str, Frames]:
        return self.model.predict(request, steps=steps, seed=seed + self.offset)

    def __getattr__(self, name: str) -> Any:
        """A model that also predicts the reported state (``predict_with_state``) keeps it, seed shifted."""
        if name == "predict_with_state":
            inner = getattr(self.__dict__["model"], name)  # AttributeError when the model has none

            def shifted(request: PredictRequest, *, steps: int | None = None, seed: int = 0) -> Any:
                return inner(request, steps=steps, seed=seed + self.offset)

            return shifted
        raise AttributeError(name)


class FrameAutoencoder:
    """Frames through a native model's frame VAE: ``E`` (latent means) then plain ``D`` (no gated residual).

    A model seen through :class:`~pilworld.world_model.resized.ResizedWorldModel` is autoencoded at its
    own size (frames area-resized down, decoded frames bilinear-resized back), as it would see them.
    """

    def __init__(
        self,
        encode: Callable[[torch.Tensor], torch.Tensor],
        decode: Callable[[torch.Tensor], torch.Tensor],
        native: tuple[int, int] | None = None,
        batch: int = 48,
    ) -> None:
        self._encode = encode
        self._decode = decode
        self.native = native  # (width, height) to autoencode at, None = the frames' own size
        self.batch = batch

    def __call__(self, frames: Frames) -> Frames:
        """uint8 [N, H, W, 3] → the autoencoded uint8 [N, H, W, 3]."""
        from pilworld.world_model.batching import resize_images
        from pilworld.world_model.latent.vae import to_uint8
        from pilworld.world_model.resized import upsample_images

        arr = np.asarray(frames, dtype=np.uint8)
        h, w = arr.shape[-3], arr.shape[-2]
        out = []
        for i in range(0, arr.shape[0], self.batch):
            x = torch.from_numpy(np.ascontiguousarray(np.moveaxis(arr[i : i + self.batch], -1, -3)))
            if self.native is not None:
                x = resize_images(x, self.native[1], self.native[0])
            with torch.no_grad():
                y = to_uint8(self._decode(self._encode(x)).clamp(-1.0, 1.0))
            if self.native is not None:
                y = upsample_images(y, h, w)
            out.append(np.moveaxis(y.numpy(), -3, -1))
        return np.ascontiguousarray(np.concatenate(out))

    def images(self, images: Mapping[str, Frames]) -> dict[str, Frames]:
        """One observation's views (each [H, W, 3]) autoencoded in one call."""
        views = list(images)
        done = self(np.stack([np.asarray(images[v]) for v in views]))
        return {v: done[i] for i, v in enumerate(views)}


def autoencoder_for(model: WorldModel) -> FrameAutoencoder | str:
    """The model's frame autoencoder, or why it has none (a string)."""
    from pilworld.world_model.resized import ResizedWorldModel

    inner: Any = model
    native: tuple[int, int] | None = None
    if isinstance(model, ResizedWorldModel):
        inner = model.model
        native = model.native_size
    encode, decode = getattr(inner, "encode", None), getattr(inner, "decode_unit", None)
    if not callable(encode) or not callable(decode):
        return f"{type(inner).__name__} has no frame autoencoder (no encode / decode_unit)"
    return FrameAutoencoder(encode, decode, native)


def load_ladder_model(path: Path, rig: RigConfig, spec: ChunkSpec, task: str) -> tuple[WorldModel, str | None, bool]:
    """(model, adapter, resized): the folder's model with ``task``'s adapter when it has one, at the rig's size."""
    from pilworld.world_model.base import RigBound
    from pilworld.world_model.loader import adapter_names, load_world_model
    from pilworld.world_model.resized import ResizedWorldModel

    check_model_folder(path)
    adapter = task if task in adapter_names(path) else None
    model: WorldModel = load_world_model(path, adapter=adapter)
    if isinstance(model, RigBound):  # a model that composites the rig's geometry uses this rig's calibration
        model.bind_rig(rig)
    info = model.info
    if set(info.views) != set(rig.cameras):
        raise ValueError(f"model: {path} predicts views {list(info.views)}, the rig has {list(rig.cameras)}")
    if info.future != spec.frames:
        raise ValueError(f"model: {path} predicts K={info.future} frames per round, the ladder uses K={spec.frames}")
    size = (rig.image_size.width, rig.image_size.height)
    resized = (info.width, info.height) != size
    if resized:
        model = ResizedWorldModel(model, height=size[1], width=size[0])
    return model, adapter, resized
