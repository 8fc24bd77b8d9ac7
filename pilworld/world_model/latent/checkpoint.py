"""World model v1 folders (the latent video model): safetensors weights beside a JSON config (never a pickle).

A model folder holds ``config.json`` (a :class:`WorldModelConfig` plus ``format``) and
``model.safetensors``. A stage-2 (fine-tuned) folder may also hold LoRA adapters, one per target
task, under ``adapters/<name>/`` (``adapter_config.json`` and ``adapter.safetensors``, peft's names);
:func:`load_latent` applies one and merges it into the weights for inference speed. Folders of every
format load through :func:`pilworld.world_model.loader.load_world_model`.
"""

from __future__ import annotations

from pathlib import Path

import torch

from pilworld.world_model.folder import CONFIG_FILE, WEIGHTS_FILE, load_weights, read_folder_config, save_folder
from pilworld.world_model.latent.config import WorldModelConfig
from pilworld.world_model.latent.lora import apply_adapter
from pilworld.world_model.latent.model import PilWorldModel

FORMAT = "pilworld-world-model/1"
ADAPTERS_DIR = "adapters"


def save_model(model: PilWorldModel, folder: str | Path, *, dtype: torch.dtype = torch.float32) -> Path:
    """Write ``model`` (weights cast to ``dtype``; float16 halves a shipped file) with its config."""
    return save_folder(model, folder, FORMAT, model.config.to_dict(), dtype=dtype)


def read_config(folder: str | Path) -> WorldModelConfig:
    path = Path(folder) / CONFIG_FILE
    data = read_folder_config(folder, FORMAT)
    try:
        return WorldModelConfig.from_dict(data)
    except (KeyError, TypeError, ValueError, AttributeError) as err:
        raise ValueError(f"{path}: not a valid world-model config ({type(err).__name__}: {err})") from None


def load_model(folder: str | Path, *, device: str | torch.device = "cpu") -> PilWorldModel:
    """The base model of a folder (no adapter), in float32, in eval mode."""
    folder = Path(folder)
    config = read_config(folder)
    model = PilWorldModel(config)
    load_weights(model, folder / WEIGHTS_FILE)
    return model.to(device).eval()


def adapter_names(folder: str | Path) -> list[str]:
    root = Path(folder) / ADAPTERS_DIR
    return sorted(p.name for p in root.iterdir() if (p / "adapter.safetensors").is_file()) if root.is_dir() else []


def load_latent(path: str | Path, *, adapter: str | None = None, device: str | torch.device = "cpu") -> PilWorldModel:
    """Load a v1 folder for inference; ``adapter`` names a LoRA adapter under ``adapters/`` to merge in."""
    folder = Path(path)
    model = load_model(folder, device=device)
    if adapter is not None:
        names = adapter_names(folder)
        if adapter not in names:
            raise ValueError(f"adapter: {adapter!r} not in {folder / ADAPTERS_DIR} (available: {names})")
        apply_adapter(model, folder / ADAPTERS_DIR / adapter, merge=True)
    return model.eval()


def export_model(
    source: str | Path,
    out: str | Path,
    *,
    adapters: list[Path] | None = None,
    dtype: torch.dtype = torch.float16,
    steps: int | None = None,
) -> Path:
    """Write a shippable copy of a model folder: weights cast to ``dtype``, the LoRA adapters of ``adapters``
    (stage-2 model folders fine-tuned from ``source``, or adapter folders) gathered under ``adapters/``, and
    optionally a new default number of sampling steps."""
    import shutil

    model = load_model(source)
    if steps is not None:
        model.config = model.config.replace(steps=steps)
    dest = save_model(model, out, dtype=dtype)
    for src in adapters or []:
        src = Path(src)
        found = (
            [src] if (src / "adapter.safetensors").is_file() else [src / ADAPTERS_DIR / n for n in adapter_names(src)]
        )
        if not found:
            raise FileNotFoundError(f"{src}: no LoRA adapter (expected adapter.safetensors or {ADAPTERS_DIR}/<task>/)")
        for folder in found:
            shutil.copytree(folder, dest / ADAPTERS_DIR / folder.name, dirs_exist_ok=True)
    return dest
