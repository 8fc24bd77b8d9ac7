"""Training checkpoints for exact resume: model, AdamW moments, EMA and the step, all in safetensors + JSON.

A checkpoint is a folder ``checkpoints/<phase>-<step:07d>/`` written under a temporary name and renamed,
so a kill mid-write leaves the previous checkpoint intact. The data order needs no saved state (it is
a function of the step, see :mod:`pilworld.world_model.training.data`).
"""

from __future__ import annotations

import json
import os
import shutil
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import torch
from safetensors.torch import load_file, save_file
from torch import nn


@dataclass(frozen=True)
class Resume:
    phase: str
    step: int  # the number of completed steps of the phase
    folder: Path


class EMA:
    """Exponential moving average of the trainable weights (what inference uses)."""

    def __init__(self, params: dict[str, nn.Parameter], decay: float) -> None:
        self.decay = decay
        self.shadow = {k: p.detach().clone() for k, p in params.items()}

    @torch.no_grad()
    def update(self, params: dict[str, nn.Parameter], step: int) -> None:
        d = min(self.decay, (1 + step) / (10 + step))  # short warm-up so early weights fade fast
        for k, p in params.items():
            self.shadow[k].mul_(d).add_(p.detach(), alpha=1 - d)


def optimizer_tensors(opt: torch.optim.Optimizer, names: dict[int, str]) -> dict[str, torch.Tensor]:
    out: dict[str, torch.Tensor] = {}
    for group in opt.param_groups:
        for p in group["params"]:
            st = opt.state.get(p)
            if not st:
                continue
            name = names[id(p)]
            for key, value in st.items():
                out[f"{name}::{key}"] = value if torch.is_tensor(value) else torch.tensor(value)
    return out


def load_optimizer_tensors(opt: torch.optim.Optimizer, names: dict[int, str], tensors: dict[str, torch.Tensor]) -> None:
    for group in opt.param_groups:
        for p in group["params"]:
            keys = {k.split("::", 1)[1]: v for k, v in tensors.items() if k.split("::", 1)[0] == names[id(p)]}
            if keys:
                opt.state[p] = {k: v.to(p.device) if v.dim() else v for k, v in keys.items()}


def save_checkpoint(
    root: Path,
    phase: str,
    step: int,
    model: nn.Module,
    opt: torch.optim.Optimizer,
    names: dict[int, str],
    ema: EMA | None,
    extra: dict[str, Any],
    keep: int = 2,
) -> Path:
    final = root / f"{phase}-{step:07d}"
    tmp = root / f".{final.name}.tmp"
    shutil.rmtree(tmp, ignore_errors=True)
    tmp.mkdir(parents=True)
    save_file({k: v.detach().contiguous() for k, v in model.state_dict().items()}, str(tmp / "model.safetensors"))
    save_file({k: v.contiguous() for k, v in optimizer_tensors(opt, names).items()}, str(tmp / "optimizer.safetensors"))
    if ema is not None:
        save_file({k: v.contiguous() for k, v in ema.shadow.items()}, str(tmp / "ema.safetensors"))
    (tmp / "state.json").write_text(json.dumps({"phase": phase, "step": step, **extra}, indent=2))
    for f in tmp.iterdir():
        with f.open("rb") as fh:
            os.fsync(fh.fileno())
    shutil.rmtree(final, ignore_errors=True)
    tmp.replace(final)
    for old in sorted(p for p in root.glob(f"{phase}-*") if p.is_dir())[:-keep]:
        shutil.rmtree(old, ignore_errors=True)
    return final


def latest_checkpoint(root: Path, phase: str) -> Resume | None:
    found = sorted(p for p in root.glob(f"{phase}-*") if p.is_dir() and (p / "state.json").is_file())
    if not found:
        return None
    state = json.loads((found[-1] / "state.json").read_text())
    return Resume(phase, int(state["step"]), found[-1])


def load_checkpoint(
    resume: Resume, model: nn.Module, opt: torch.optim.Optimizer, names: dict[int, str], ema: EMA | None
) -> None:
    model.load_state_dict(load_file(str(resume.folder / "model.safetensors")))
    load_optimizer_tensors(opt, names, load_file(str(resume.folder / "optimizer.safetensors")))
    if ema is not None and (resume.folder / "ema.safetensors").is_file():
        ema.shadow = dict(load_file(str(resume.folder / "ema.safetensors")))
