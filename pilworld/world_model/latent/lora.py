"""Stage-2 fine-tuning with LoRA through peft (paper §4: "fine-tune the model on target-task trajectory
clips using LoRA").

Ψ_θ is a plain ``nn.Module``, so adapters go in with ``peft.inject_adapter_in_model`` on the attention
and MLP projections (:data:`~pilworld.world_model.latent.denoiser.LORA_TARGETS`); only the adapter weights
train. Adapters are saved in peft's file names (``adapter_config.json``, ``adapter.safetensors``).
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import torch
from safetensors.torch import load_file

from pilworld.world_model.folder import save_tensors
from pilworld.world_model.latent.denoiser import LORA_TARGETS
from pilworld.world_model.latent.model import PilWorldModel


def _peft() -> Any:
    try:
        import peft
    except ImportError as exc:  # pragma: no cover - peft is a core dependency
        raise ImportError("LoRA fine-tuning needs peft: pip install peft") from exc
    return peft


def add_lora(model: PilWorldModel, rank: int, alpha: float | None = None) -> list[str]:
    """Insert LoRA adapters into Ψ_θ and freeze everything else; returns the trainable parameter names."""
    if isinstance(rank, bool) or not isinstance(rank, int) or rank < 1:
        raise ValueError(f"lora_rank: expected an integer >= 1, got {rank!r}")
    peft = _peft()
    config = peft.LoraConfig(r=rank, lora_alpha=alpha or rank, target_modules=list(LORA_TARGETS), lora_dropout=0.0)
    peft.inject_adapter_in_model(config, model.denoiser)
    for name, p in model.named_parameters():
        p.requires_grad_("lora_" in name)
    return [n for n, p in model.named_parameters() if p.requires_grad]


def adapter_state(model: PilWorldModel) -> dict[str, torch.Tensor]:
    peft = _peft()
    state: dict[str, torch.Tensor] = peft.get_peft_model_state_dict(model.denoiser)
    return state


def save_adapter(model: PilWorldModel, folder: Path, rank: int, alpha: float | None = None) -> None:
    from pilworld.io.atomic import write_json

    folder.mkdir(parents=True, exist_ok=True)
    save_tensors(folder / "adapter.safetensors", {k: v.half() for k, v in adapter_state(model).items()})
    write_json(
        folder / "adapter_config.json",
        {"r": rank, "lora_alpha": alpha or rank, "target_modules": list(LORA_TARGETS), "peft_type": "LORA"},
    )


def apply_adapter(model: PilWorldModel, folder: Path, *, merge: bool) -> None:
    """Load an adapter saved by :func:`save_adapter` into ``model``; ``merge`` folds it into the weights."""
    cfg_path, weights = folder / "adapter_config.json", folder / "adapter.safetensors"
    for p in (cfg_path, weights):
        if not p.is_file():
            raise FileNotFoundError(f"{p}: missing LoRA adapter file")
    cfg = json.loads(cfg_path.read_text())
    add_lora(model, int(cfg["r"]), float(cfg["lora_alpha"]))
    peft = _peft()
    state = {k: v.float() for k, v in load_file(str(weights)).items()}
    result = peft.set_peft_model_state_dict(model.denoiser, state)
    unexpected = getattr(result, "unexpected_keys", [])
    if unexpected:
        raise ValueError(f"{weights}: adapter weights do not fit the model (unexpected {unexpected[:5]})")
    if merge:
        from peft.tuners.lora import LoraLayer

        for module in model.denoiser.modules():
            if isinstance(module, LoraLayer):
                module.merge()
    for param in model.parameters():
        param.requires_grad_(False)
