"""World model v2 folders: ``config.json`` (format ``pilworld-composite-world-model/1``) + ``model.safetensors``."""

from __future__ import annotations

from pathlib import Path

import torch

from pilworld.world_model.composite.model import CompositeConfig, CompositeWorldModel
from pilworld.world_model.folder import (
    CONFIG_FILE,
    WEIGHTS_FILE,
    folder_format,
    load_weights,
    read_folder_config,
    save_folder,
)

FORMAT = "pilworld-composite-world-model/1"


def save_composite(model: CompositeWorldModel, folder: str | Path, *, dtype: torch.dtype = torch.float32) -> Path:
    return save_folder(model, folder, FORMAT, model.config.to_dict(), dtype=dtype)


def is_composite(folder: str | Path) -> bool:
    return folder_format(folder) == FORMAT


def load_composite(folder: str | Path) -> CompositeWorldModel:
    root = Path(folder)
    data = read_folder_config(root, FORMAT)
    try:
        config = CompositeConfig.from_dict(data)
    except (KeyError, TypeError, ValueError, AttributeError) as err:
        raise ValueError(
            f"{root / CONFIG_FILE}: not a valid world-model config ({type(err).__name__}: {err})"
        ) from None
    model = CompositeWorldModel(config)
    load_weights(model, root / WEIGHTS_FILE)
    return model.eval()
