"""World-model checkpoints: safetensors weights beside a JSON config (never a pickle).

A model folder holds ``config.json`` (a :class:`WorldModelConfig` plus ``format``) and
``model.safetensors``. A stage-2 (fine-tuned) folder may also hold LoRA adapters, one per target
task, under ``adapters/<name>/`` (``adapter_config.json`` and ``adapter.safetensors``, peft's names);
:func:`load_world_model` applies one and merges it into the weights for inference speed.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import torch
from safetensors.torch import load_file, save_file
from torch import nn

from pilworld.data.atomic import atomic_write, write_json
from pilworld.world_model.config import WorldModelConfig
from pilworld.world_model.model import PilWorldModel

FORMAT = "pilworld-world-model/1"
CONFIG_FILE = "config.json"
WEIGHTS_FILE = "model.safetensors"
ADAPTERS_DIR = "adapters"


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


def save_model(model: PilWorldModel, folder: str | Path, *, dtype: torch.dtype = torch.float32) -> Path:
    """Write ``model`` (weights cast to ``dtype``; float16 halves a shipped file) with its config."""
    return save_folder(model, folder, FORMAT, model.config.to_dict(), dtype=dtype)


def read_config(folder: str | Path) -> WorldModelConfig:
    path = Path(folder) / CONFIG_FILE
    if not path.is_file():
        raise FileNotFoundError(f"{path}: no world-model config (expected {CONFIG_FILE} beside {WEIGHTS_FILE})")
    from pilworld.io.run_folder import read_json_object

    data = read_json_object(path, "world model")
    if data.get("format") != FORMAT:
        raise ValueError(f"{path}: format {data.get('format')!r} is not {FORMAT!r}")
    try:
        return WorldModelConfig.from_dict(data["config"])
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


def load_world_model(
    path: str | Path, *, adapter: str | None = None, device: str | torch.device = "cpu"
) -> PilWorldModel:
    """Load a model folder for inference; ``adapter`` names a LoRA adapter under ``adapters/`` to merge in."""
    from pilworld.world_model.lora import apply_adapter

    folder = Path(path)
    if not folder.is_dir():
        raise FileNotFoundError(f"{folder}: not a world-model folder (expected {CONFIG_FILE} and {WEIGHTS_FILE})")
    from pilworld.world_model.composite.checkpoint import is_composite, load_composite

    if is_composite(folder):  # world model v2: one model for every task, no adapters
        if adapter is not None:
            raise ValueError(f"adapter: {folder} is a v2 (composite) world model, which has no task adapters")
        return load_composite(folder)  # type: ignore[return-value]
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
