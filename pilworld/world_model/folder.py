"""A world-model folder on disk: ``config.json`` (its ``format`` and config) beside ``model.safetensors``.

Never a pickle. Every native format (world model v1, the latent video model; v2, the composite) writes
this layout; :mod:`pilworld.world_model.loader` reads a folder's ``format`` and hands it to the format's
own loader.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import torch
from safetensors.torch import load_file, save_file
from torch import nn

from pilworld.io.atomic import atomic_write, write_json
from pilworld.io.run_folder import read_json_object

CONFIG_FILE = "config.json"
WEIGHTS_FILE = "model.safetensors"


def save_tensors(path: Path, tensors: dict[str, torch.Tensor], metadata: dict[str, str] | None = None) -> None:
    clean = {k: v.detach().contiguous().cpu() for k, v in tensors.items()}
    atomic_write(path, lambda tmp: save_file(clean, str(tmp), metadata=metadata))


def save_folder(
    model: nn.Module, folder: str | Path, fmt: str, config: dict[str, Any], *, dtype: torch.dtype = torch.float32
) -> Path:
    """Write ``model``'s weights (cast to ``dtype``) and ``config`` under the folder format ``fmt``."""
    out = Path(folder)
    out.mkdir(parents=True, exist_ok=True)
    state = {k: v.to(dtype) if v.is_floating_point() else v for k, v in model.state_dict().items()}
    save_tensors(out / WEIGHTS_FILE, state, {"format": fmt})
    write_json(out / CONFIG_FILE, {"format": fmt, "config": config})
    return out


def read_tensors(path: Path) -> dict[str, torch.Tensor]:
    """The tensors of a safetensors file; a truncated, empty or foreign file is one line naming it."""
    try:
        return load_file(str(path))
    except FileNotFoundError:
        raise FileNotFoundError(f"{path}: missing weights file") from None
    except Exception as err:  # safetensors raises its own SafetensorError (and OSError, RuntimeError)
        detail = " ".join(str(err).split()) or type(err).__name__
        raise ValueError(f"{path}: damaged weights, not a readable safetensors file ({detail})") from None


def load_weights(model: nn.Module, weights: Path) -> None:
    """Load a folder's weights (as float32) into ``model``; ``ValueError`` when they do not fit its config."""
    if not weights.is_file():
        raise FileNotFoundError(f"{weights}: missing world-model weights")
    state = {k: v.float() if v.is_floating_point() else v for k, v in read_tensors(weights).items()}
    missing, unexpected = model.load_state_dict(state, strict=False)
    if missing or unexpected:
        raise ValueError(
            f"{weights}: weights do not fit the config (missing {missing[:5]}, unexpected {unexpected[:5]})"
        )


def folder_format(folder: str | Path) -> str | None:
    """The ``format`` a folder's ``config.json`` names; None when it has no readable one (no error: the
    loader then tries the layouts that carry no config of ours, and names what it expected)."""
    path = Path(folder) / CONFIG_FILE
    if not path.is_file():
        return None
    try:
        data = json.loads(path.read_text())
    except (json.JSONDecodeError, UnicodeDecodeError):
        return None
    fmt = data.get("format") if isinstance(data, dict) else None
    return fmt if isinstance(fmt, str) else None


def read_folder_config(folder: str | Path, fmt: str) -> dict[str, Any]:
    """The ``config`` object of a ``fmt`` folder; one line naming the file when it is missing or not ``fmt``."""
    path = Path(folder) / CONFIG_FILE
    if not path.is_file():
        raise FileNotFoundError(f"{path}: no world-model config (expected {CONFIG_FILE} beside {WEIGHTS_FILE})")
    data = read_json_object(path, "world model")
    if data.get("format") != fmt:
        raise ValueError(f"{path}: format {data.get('format')!r} is not {fmt!r}")
    config = data.get("config")
    if not isinstance(config, dict):
        raise ValueError(f"{path}: not a valid world-model config (no 'config' object)")
    return config
