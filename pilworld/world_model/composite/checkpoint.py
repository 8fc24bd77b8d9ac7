"""World model v2 folders: ``config.json`` (format ``pilworld-composite-world-model/1``) + ``model.safetensors``."""

from __future__ import annotations

import json
from pathlib import Path

import torch
from safetensors.torch import load_file

from pilworld.data.atomic import write_json
from pilworld.world_model.composite.model import CompositeConfig, CompositeWorldModel

FORMAT = "pilworld-composite-world-model/1"


def save_composite(model: CompositeWorldModel, folder: str | Path, *, dtype: torch.dtype = torch.float32) -> Path:
    from pilworld.world_model.checkpoint import CONFIG_FILE, WEIGHTS_FILE, save_tensors

    out = Path(folder)
    out.mkdir(parents=True, exist_ok=True)
    state = {k: v.to(dtype) if v.is_floating_point() else v for k, v in model.state_dict().items()}
    save_tensors(out / WEIGHTS_FILE, state, {"format": FORMAT})
    write_json(out / CONFIG_FILE, {"format": FORMAT, "config": model.config.to_dict()})
    return out


def is_composite(folder: str | Path) -> bool:
    from pilworld.world_model.checkpoint import CONFIG_FILE

    path = Path(folder) / CONFIG_FILE
    if not path.is_file():
        return False
    try:
        return bool(json.loads(path.read_text()).get("format") == FORMAT)
    except json.JSONDecodeError:
        return False


def load_composite(folder: str | Path) -> CompositeWorldModel:
    from pilworld.world_model.checkpoint import CONFIG_FILE, WEIGHTS_FILE

    root = Path(folder)
    data = json.loads((root / CONFIG_FILE).read_text())
    if data.get("format") != FORMAT:
        raise ValueError(f"{root / CONFIG_FILE}: format {data.get('format')!r} is not {FORMAT!r}")
    model = CompositeWorldModel(CompositeConfig.from_dict(data["config"]))
    weights = root / WEIGHTS_FILE
    if not weights.is_file():
        raise FileNotFoundError(f"{weights}: missing world-model weights")
    state = {k: v.float() if v.is_floating_point() else v for k, v in load_file(str(weights)).items()}
    missing, unexpected = model.load_state_dict(state, strict=False)
    if missing or unexpected:
        raise ValueError(
            f"{weights}: weights do not fit the config (missing {missing[:5]}, unexpected {unexpected[:5]})"
        )
    return model.eval()
