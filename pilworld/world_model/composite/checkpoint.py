"""World model v2 folders: ``config.json`` (format ``pilworld-composite-world-model/1``) + ``model.safetensors``."""

from __future__ import annotations

import json
from pathlib import Path

import torch

from pilworld.world_model.checkpoint import CONFIG_FILE, WEIGHTS_FILE, load_weights, save_folder
from pilworld.world_model.composite.model import CompositeConfig, CompositeWorldModel

FORMAT = "pilworld-composite-world-model/1"


def save_composite(model: CompositeWorldModel, folder: str | Path, *, dtype: torch.dtype = torch.float32) -> Path:
    return save_folder(model, folder, FORMAT, model.config.to_dict(), dtype=dtype)


def is_composite(folder: str | Path) -> bool:
    path = Path(folder) / CONFIG_FILE
    if not path.is_file():
        return False
    try:
        data = json.loads(path.read_text())
        return isinstance(data, dict) and data.get("format") == FORMAT
    except (json.JSONDecodeError, UnicodeDecodeError):
        return False


def load_composite(folder: str | Path) -> CompositeWorldModel:
    root = Path(folder)
    from pilworld.io.run_folder import read_json_object

    data = read_json_object(root / CONFIG_FILE, "world model")
    if data.get("format") != FORMAT:
        raise ValueError(f"{root / CONFIG_FILE}: format {data.get('format')!r} is not {FORMAT!r}")
    try:
        config = CompositeConfig.from_dict(data["config"])
    except (KeyError, TypeError, ValueError, AttributeError) as err:
        raise ValueError(
            f"{root / CONFIG_FILE}: not a valid world-model config ({type(err).__name__}: {err})"
        ) from None
    model = CompositeWorldModel(config)
    load_weights(model, root / WEIGHTS_FILE)
    return model.eval()
