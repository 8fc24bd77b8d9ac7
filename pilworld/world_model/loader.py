"""One loader for every world-model format, keyed by what the folder says it is.

A native folder names its ``format`` in ``config.json`` (:mod:`.folder`); a diffusers-format Wan2.1
folder is recognised by its ``transformer/`` and ``vae/`` subfolders. Each format has one entry in
:data:`FORMATS`: how to load it and which task adapters it holds. Callers get a
:class:`~pilworld.world_model.base.WorldModel` and query its optional capabilities with ``isinstance``
(:mod:`.base`).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import torch

from pilworld.world_model.base import WorldModel, WorldModelInfo
from pilworld.world_model.folder import CONFIG_FILE, WEIGHTS_FILE, folder_format


@dataclass(frozen=True)
class Format:
    """A world-model folder format: its name (``config.json``'s ``format``), what it is, how to load it."""

    name: str
    what: str
    # (folder, adapter, device, info) -> model; ``info`` only matters to a folder that does not carry it
    load: Callable[[Path, str | None, str | torch.device, WorldModelInfo | None], WorldModel]
    adapters: Callable[[Path], list[str]] = lambda _folder: []


def _latent(folder: Path, adapter: str | None, device: str | torch.device, info: WorldModelInfo | None) -> WorldModel:
    from pilworld.world_model.latent.checkpoint import load_latent

    return load_latent(folder, adapter=adapter, device=device)


def _latent_adapters(folder: Path) -> list[str]:
    from pilworld.world_model.latent.checkpoint import adapter_names

    return adapter_names(folder)


def _composite(
    folder: Path, adapter: str | None, device: str | torch.device, info: WorldModelInfo | None
) -> WorldModel:
    from pilworld.world_model.composite.checkpoint import load_composite

    if adapter is not None:
        raise ValueError(f"adapter: {folder} is a v2 (composite) world model, which has no task adapters")
    return load_composite(folder).to(device)


def _wan(folder: Path, adapter: str | None, device: str | torch.device, info: WorldModelInfo | None) -> WorldModel:
    from pilworld.world_model.wan.backend import WanWorldModel

    if adapter is not None:
        raise ValueError(f"adapter: {folder} is a Wan2.1 world model, which has no task adapters")
    return WanWorldModel.from_pretrained(folder, info, device=device)


# Imports of each format's code happen when a folder of that format is loaded: torch-only users never
# import diffusers, and a format's modules stay independent of each other.
FORMATS: dict[str, Format] = {
    f.name: f
    for f in (
        Format("pilworld-composite-world-model/1", "world model v2 (composite)", _composite),
        Format("pilworld-world-model/1", "world model v1 (latent video)", _latent, _latent_adapters),
        Format("pilworld-wan2.1/1", "Wan2.1 (diffusers)", _wan),
    )
}
WAN_STOCK = Format("wan2.1-diffusers", "a stock Wan2.1 folder (diffusers)", _wan)


def format_of(path: str | Path) -> Format:
    """The :class:`Format` of a world-model folder; one line naming the folder and what was expected."""
    from pilworld.world_model.wan.backend import is_wan_folder

    folder = Path(path)
    if not folder.is_dir():
        raise FileNotFoundError(f"{folder}: not a world-model folder (expected {CONFIG_FILE} and {WEIGHTS_FILE})")
    name = folder_format(folder)
    if name in FORMATS:
        return FORMATS[name]
    if is_wan_folder(folder):
        return WAN_STOCK
    known = ", ".join(FORMATS)
    if name is None:
        raise FileNotFoundError(
            f"{folder}: not a world-model folder (no readable {CONFIG_FILE} naming a format, and no Wan2.1 "
            f"transformer/ and vae/); formats: {known}"
        )
    raise ValueError(f"{folder / CONFIG_FILE}: format {name!r} is not a world-model format ({known})")


def load_world_model(
    path: str | Path,
    *,
    adapter: str | None = None,
    device: str | torch.device = "cpu",
    info: WorldModelInfo | None = None,
) -> WorldModel:
    """Load any world-model folder for inference, in eval mode.

    ``adapter``: a v1 task adapter to merge in (other formats have none). ``info``: the views, image
    size, K and H_h, for a stock Wan2.1 folder that does not say them (every other format does)."""
    folder = Path(path)
    return format_of(folder).load(folder, adapter, device, info)


def adapter_names(path: str | Path) -> list[str]:
    """The task adapters a world-model folder holds (only v1 folders have any)."""
    folder = Path(path)
    return format_of(folder).adapters(folder)
