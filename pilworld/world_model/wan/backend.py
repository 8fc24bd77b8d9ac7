"""The Wan2.1 backend: diffusers' ``WanTransformer3DModel`` + ``AutoencoderKLWan`` behind :class:`WorldModel`.

Conditioning design (paper appendix "Latent Training Objective": only the future latents are noised):

* **Views jointly.** Every view is encoded by the VAE on its own (so VAE convolutions never mix two
  cameras), then the V latent videos are tiled side by side along the latent width, head view leftmost.
  One transformer pass attends over all views. ``height`` and ``width`` must be multiples of 16
  (the VAE's 8× times the patch's 2×) so no token straddles two views.
* **Time axis** of the tiled latent video: ``[history (H_h) | current (1) | future (n_f)]``. History
  and current frames are encoded one frame each (a 1-frame video is a valid 4k+1 clip), one latent
  frame per history frame; invalid history frames (before the episode) become zero latents. The
  future is the causal tail of the clip ``[current, f_1..f_K]`` padded to 4k+1 (:func:`wan_frame_count`):
  its first latent is exactly the current frame's latent (the VAE encodes frame 0 alone), the rest
  are the n_f future latents; decoding ``[current, future]`` and dropping frame 0 and the padding
  gives the K frames.
* **Channels** fed to the transformer (``in_channels = 2·z_dim + 1``): the latent stream (clean at
  context frames, noisy at future frames) | a known-mask (1 at valid history and current) | the
  control latents. The control video Γ(A) is encoded as the clip ``[black, c_1..c_K]`` padded the
  same way, so its latents align with the future latents; they sit at the head view's tile of the
  future frames, zeros elsewhere. Actions themselves are not read: Γ carries them.
* **Noise level per token** (as Wan2.2 TI2V does with the same transformer): context tokens get
  timestep 0, future tokens the sampler's timestep; only future outputs are used.
* **Instruction**: no T5; a hashed bag-of-words embedding (:class:`HashedInstructionEncoder`,
  deterministic, offline, learnable) projected to the transformer's ``text_dim``.
* **Sampler**: diffusers' ``FlowMatchEulerDiscreteScheduler`` (velocity prediction, Euler steps, Wan's
  ``shift``), a fresh instance per call because it keeps a step counter.

A stock Wan2.1 T2V folder (``in_channels == z_dim``) is accepted: its patch embedding is widened with
zero weights for the mask and control channels, so it starts as the pretrained T2V model.
"""

from __future__ import annotations

import hashlib
import json
import re
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
import torch
from numpy.typing import NDArray
from torch import nn

from pilworld.types import STATE_DIM
from pilworld.world_model.base import PredictRequest, WorldModelBatch, WorldModelInfo, predict_one
from pilworld.world_model.folder import folder_format, read_folder_config

if TYPE_CHECKING:  # the defining modules: mypy would resolve diffusers' top level to its no-torch dummies
    from diffusers.models.autoencoders.autoencoder_kl_wan import AutoencoderKLWan
    from diffusers.models.transformers.transformer_wan import WanTransformer3DModel

_EXTRA = "pip install 'pilworld[wan]'"
FORMAT = "pilworld-wan2.1/1"  # config.json of a folder save_pretrained wrote: the views, sizes and sampler
_SHIFT = 5.0  # Wan2.1's flow shift for 480p when the folder has no scheduler config


def _diffusers() -> Any:
    """Import diffusers only when a Wan model is built, so the rest of pilworld runs without it."""
    try:
        import diffusers
    except ImportError as e:
        raise ImportError(f"the Wan2.1 world model needs diffusers: {_EXTRA}") from e
    return diffusers


def wan_frame_count(n: int, temporal: int = 4) -> tuple[int, int]:
    """``(padded, pad)``: the VAE encodes ``padded = temporal·k + 1 >= n`` frames; repeat the last frame
    ``pad`` times before encoding and drop that many after decoding. E.g. K=15 future frames after the
    current frame: ``wan_frame_count(16) == (17, 1)``."""
    if isinstance(n, bool) or not isinstance(n, int) or n < 1:
        raise ValueError(f"n: expected a frame count >= 1, got {n!r}")
    if isinstance(temporal, bool) or not isinstance(temporal, int) or temporal < 1:
        raise ValueError(f"temporal: expected a compression factor >= 1, got {temporal!r}")
    padded = -(-(n - 1) // temporal) * temporal + 1
    return padded, padded - n


class HashedInstructionEncoder(nn.Module):
    """Instruction → ``[B, max_tokens, text_dim]``: each lower-cased word hashed (blake2b, stable across
    runs, unlike ``hash``) into a learned table, then projected; padding rows are zero like Wan's T5."""

    def __init__(self, text_dim: int, *, buckets: int = 4096, dim: int = 64, max_tokens: int = 32, seed: int = 0):
        super().__init__()
        self.config = {"text_dim": text_dim, "buckets": buckets, "dim": dim, "max_tokens": max_tokens}
        self.table = nn.Embedding(buckets, dim)
        self.proj = nn.Linear(dim, text_dim)
        g = torch.Generator().manual_seed(seed)  # own generator: building a model must not move global RNG
        with torch.no_grad():
            self.table.weight.copy_(torch.randn(buckets, dim, generator=g))
            self.proj.weight.copy_(torch.randn(text_dim, dim, generator=g) / dim**0.5)
            self.proj.bias.zero_()

    def token_ids(self, text: str) -> list[int]:
        n = int(self.config["buckets"])
        words = re.findall(r"[a-z0-9]+", text.lower())[: int(self.config["max_tokens"])]
        return [int.from_bytes(hashlib.blake2b(w.encode(), digest_size=8).digest(), "little") % n for w in words]

    def forward(self, instructions: list[str]) -> torch.Tensor:
        L = int(self.config["max_tokens"])
        ids = torch.zeros(len(instructions), L, dtype=torch.long, device=self.table.weight.device)
        mask = torch.zeros(len(instructions), L, 1, device=self.table.weight.device)
        for i, text in enumerate(instructions):
            tok = self.token_ids(text)
            ids[i, : len(tok)] = torch.tensor(tok, dtype=torch.long)
            mask[i, : len(tok)] = 1.0
        out: torch.Tensor = self.proj(self.table(ids)) * mask
        return out

    def save(self, folder: Path) -> None:
        from safetensors.torch import save_file

        folder.mkdir(parents=True, exist_ok=True)
        (folder / "config.json").write_text(json.dumps(self.config))
        save_file({k: v.contiguous().cpu() for k, v in self.state_dict().items()}, str(folder / "model.safetensors"))

    @classmethod
    def load(cls, folder: Path) -> HashedInstructionEncoder:
        from safetensors.torch import load_file

        cfg = json.loads((folder / "config.json").read_text())
        enc = cls(int(cfg.pop("text_dim")), **{k: int(v) for k, v in cfg.items()})
        enc.load_state_dict(load_file(str(folder / "model.safetensors")))
        return enc


def _widen_patch_embedding(transformer: WanTransformer3DModel, in_channels: int) -> None:
    """Give a stock T2V transformer the mask and control input channels, zero-initialised (no effect yet)."""
    old: nn.Conv3d = transformer.patch_embedding
    new = nn.Conv3d(in_channels, old.out_channels, old.kernel_size, old.stride)  # type: ignore[arg-type]
    new = new.to(device=old.weight.device, dtype=old.weight.dtype)
    with torch.no_grad():
        new.weight.zero_()
        new.weight[:, : old.in_channels] = old.weight
        assert old.bias is not None and new.bias is not None
        new.bias.copy_(old.bias)
    transformer.patch_embedding = new
    transformer.register_to_config(in_channels=in_channels)  # type: ignore[no-untyped-call]  # so save_pretrained records it


WAN_LAYOUT = "a diffusers-format Wan2.1 folder with transformer/ and vae/ subfolders (config.json + weights)"


def is_wan_folder(folder: str | Path) -> bool:
    root = Path(folder)
    return all((root / sub / "config.json").is_file() for sub in ("transformer", "vae"))


def _saved_settings(folder: Path) -> tuple[WorldModelInfo, int] | None:
    """The info and default steps :meth:`WanWorldModel.save_pretrained` wrote; None for a stock folder."""
    if folder_format(folder) != FORMAT:
        return None
    c = read_folder_config(folder, FORMAT)
    try:
        info = WorldModelInfo(
            views=tuple(c["views"]),
            height=c["height"],
            width=c["width"],
            future=c["future"],
            history=c["history"],
            action_dim=c.get("action_dim", STATE_DIM),
        )
        return info, int(c.get("default_steps", 30))
    except (KeyError, TypeError, ValueError) as err:
        raise ValueError(f"{folder / 'config.json'}: not a valid Wan2.1 settings object ({err})") from None


class WanWorldModel:
    """A Wan2.1 video diffusion backbone as a :class:`~pilworld.world_model.base.WorldModel`."""

    def __init__(
        self,
        info: WorldModelInfo,
        transformer: WanTransformer3DModel,
        vae: AutoencoderKLWan,
        *,
        instruction_encoder: HashedInstructionEncoder | None = None,
        flow_shift: float = _SHIFT,
        default_steps: int = 30,
    ) -> None:
        tcfg: dict[str, Any] = dict(transformer.config)
        vcfg: dict[str, Any] = dict(vae.config)
        self.z_dim = int(vcfg["z_dim"])
        self.temporal = int(vcfg.get("scale_factor_temporal") or 4)
        spatial = int(vcfg.get("scale_factor_spatial") or 8)
        p_t, p_h, p_w = (int(p) for p in tcfg["patch_size"])
        if p_t != 1:
            raise ValueError(
                f"transformer patch_size: expected a time patch of 1 (one token per latent frame), got {p_t}"
            )
        if tcfg["in_channels"] != 2 * self.z_dim + 1 or tcfg["out_channels"] != self.z_dim:
            raise ValueError(
                f"transformer in/out channels: expected {2 * self.z_dim + 1}/{self.z_dim} (latent + mask + control), "
                f"got {tcfg['in_channels']}/{tcfg['out_channels']}"
            )
        for name, size, p in (("height", info.height, p_h), ("width", info.width, p_w)):
            if size % (spatial * p):
                raise ValueError(
                    f"{name}: expected a multiple of {spatial * p} (VAE {spatial}x, patch {p}), got {size}"
                )
        if isinstance(default_steps, bool) or not isinstance(default_steps, int) or default_steps < 1:
            raise ValueError(f"default_steps: expected an integer >= 1, got {default_steps!r}")
        padded, self.pad = wan_frame_count(1 + info.future, self.temporal)
        self.n_future = (padded - 1) // self.temporal  # future latent frames
        self.lat_h, self.lat_w = info.height // spatial, info.width // spatial
        grid = (info.history + 1 + self.n_future, self.lat_h // p_h, len(info.views) * self.lat_w // p_w)
        if max(grid) > int(tcfg["rope_max_seq_len"]):
            raise ValueError(
                f"token grid (frames, rows, cols) {grid} exceeds rope_max_seq_len {tcfg['rope_max_seq_len']}"
            )
        self._info = info
        self.tokens_per_frame = grid[1] * grid[2]
        self.transformer = transformer.eval()
        self.vae = vae.eval()
        self.text = (instruction_encoder or HashedInstructionEncoder(int(tcfg["text_dim"]))).eval()
        self.text.to(transformer.device)
        self.flow_shift = float(flow_shift)
        self.default_steps = default_steps
        self._mean = torch.tensor(vcfg["latents_mean"], dtype=torch.float32).view(1, -1, 1, 1, 1)
        self._std = torch.tensor(vcfg["latents_std"], dtype=torch.float32).view(1, -1, 1, 1, 1)

    @classmethod
    def tiny_random(cls, info: WorldModelInfo, seed: int = 0, **kwargs: Any) -> WanWorldModel:
        """Random weights at toy size (the configs diffusers' own Wan tests use), for CPU tests."""
        d = _diffusers()
        with torch.random.fork_rng(devices=[]):
            torch.manual_seed(seed)
            vae = d.AutoencoderKLWan(base_dim=3, z_dim=16, dim_mult=[1, 1, 1, 1], num_res_blocks=1)
            transformer = d.WanTransformer3DModel(
                patch_size=(1, 2, 2),
                num_attention_heads=2,
                attention_head_dim=12,
                in_channels=33,
                out_channels=16,
                text_dim=32,
                ffn_dim=32,
                num_layers=2,
                rope_max_seq_len=32,
            )
        kwargs.setdefault("default_steps", 2)
        enc = HashedInstructionEncoder(32, buckets=256, dim=16, max_tokens=8, seed=seed)
        return cls(info, transformer, vae, instruction_encoder=enc, **kwargs)

    @classmethod
    def from_pretrained(
        cls,
        folder: Path,
        info: WorldModelInfo | None = None,
        *,
        device: str | torch.device = "cpu",
        torch_dtype: torch.dtype = torch.float32,
        flow_shift: float | None = None,
        default_steps: int | None = None,
    ) -> WanWorldModel:
        """Load a local diffusers-format Wan2.1 folder (``transformer/``, ``vae/``; optional ``scheduler/``
        and ``instruction_encoder/``). Never downloads. The VAE stays float32, as Wan recommends.

        ``info`` (views, image size, K, H_h): from the folder's ``config.json`` when :meth:`save_pretrained`
        wrote one, else it must be given (a stock Wan2.1 folder knows nothing of the rig)."""
        folder = Path(folder)
        if not folder.is_dir():
            raise FileNotFoundError(f"Wan2.1 folder {folder} does not exist; expected {WAN_LAYOUT}")
        for sub in ("transformer", "vae"):
            if not (folder / sub / "config.json").is_file():
                raise FileNotFoundError(f"{folder / sub / 'config.json'} not found; expected {WAN_LAYOUT}")
        saved = _saved_settings(folder)
        if info is None:
            if saved is None:
                raise ValueError(
                    f"{folder}: a stock Wan2.1 folder does not say which views, image size, K and H_h to predict; "
                    "pass the rig's (the paired runner does) or save it with WanWorldModel.save_pretrained"
                )
            info = saved[0]
        if default_steps is None:
            default_steps = saved[1] if saved is not None else 30
        d = _diffusers()
        transformer = d.WanTransformer3DModel.from_pretrained(
            str(folder / "transformer"), local_files_only=True, torch_dtype=torch_dtype
        )
        vae = d.AutoencoderKLWan.from_pretrained(str(folder / "vae"), local_files_only=True, torch_dtype=torch.float32)
        z = int(vae.config["z_dim"])
        if transformer.config["in_channels"] == z:
            _widen_patch_embedding(transformer, 2 * z + 1)
        enc_dir = folder / "instruction_encoder"
        enc = HashedInstructionEncoder.load(enc_dir) if enc_dir.is_dir() else None
        if flow_shift is None:  # official folders ship UniPC with "flow_shift"; ours FlowMatchEuler with "shift"
            sched = folder / "scheduler" / "scheduler_config.json"
            cfg = json.loads(sched.read_text()) if sched.is_file() else {}
            flow_shift = float(cfg.get("flow_shift", cfg.get("shift", _SHIFT)))
        model = cls(
            info,
            transformer.to(device),
            vae.to(device),
            instruction_encoder=enc,
            flow_shift=flow_shift,
            default_steps=default_steps,
        )
        return model

    def save_pretrained(self, folder: Path) -> None:
        """Write a folder :meth:`from_pretrained` reads back (transformer, vae, scheduler, instruction encoder,
        and ``config.json``: the views, image size, K, H_h and default steps)."""
        from pilworld.io.atomic import write_json

        folder = Path(folder)
        info = self._info
        config = {
            "views": list(info.views),
            "height": info.height,
            "width": info.width,
            "future": info.future,
            "history": info.history,
            "action_dim": info.action_dim,
            "default_steps": self.default_steps,
        }
        folder.mkdir(parents=True, exist_ok=True)
        write_json(folder / "config.json", {"format": FORMAT, "config": config})
        self.transformer.save_pretrained(str(folder / "transformer"))
        self.vae.save_pretrained(str(folder / "vae"))
        _diffusers().FlowMatchEulerDiscreteScheduler(shift=self.flow_shift).save_pretrained(str(folder / "scheduler"))
        self.text.save(folder / "instruction_encoder")

    @property
    def info(self) -> WorldModelInfo:
        return self._info

    @property
    def device(self) -> torch.device:
        return torch.device(self.transformer.device)

    def _encode(self, frames: torch.Tensor) -> torch.Tensor:
        """uint8 ``[N, T, 3, H, W]`` (T = 4k+1) → normalised latents ``[N, z, 1 + k, h, w]`` (posterior mode)."""
        x = frames.permute(0, 2, 1, 3, 4).to(self.vae.dtype) / 127.5 - 1.0
        lat: torch.Tensor = self.vae.encode(x).latent_dist.mode().float()
        return (lat - self._mean.to(lat.device)) / self._std.to(lat.device)

    def _decode(self, latents: torch.Tensor) -> torch.Tensor:
        """Normalised latents ``[N, z, t, h, w]`` → uint8 ``[N, T, 3, H, W]``."""
        lat = latents * self._std.to(latents.device) + self._mean.to(latents.device)
        x: torch.Tensor = self.vae.decode(lat.to(self.vae.dtype), return_dict=False)[0].float()
        return ((x.clamp(-1, 1) + 1) * 127.5).round().to(torch.uint8).permute(0, 2, 1, 3, 4)

    def _tile(self, lat: torch.Tensor) -> torch.Tensor:
        """``[B, V, z, t, h, w]`` → ``[B, z, t, h, V·w]``: views side by side, head view leftmost."""
        B, V, z, t, h, w = lat.shape
        return lat.permute(0, 2, 3, 4, 1, 5).reshape(B, z, t, h, V * w)

    def _conditioning(self, batch: WorldModelBatch) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
        """Clean context latents ``[B, z, H_h+1, h, V·w]``, the mask + control channels for every latent
        frame ``[B, 1+z, H_h+1+n_f, h, V·w]``, and the current latents per view ``[B·V, z, 1, h, w]``."""
        B, V, Hh, H, W = batch.size, len(self._info.views), self._info.history, self._info.height, self._info.width
        frames = torch.cat([batch.history, batch.current[:, :, None]], dim=2)  # [B, V, Hh+1, 3, H, W]
        lat = self._encode(frames.reshape(B * V * (Hh + 1), 1, 3, H, W))  # one latent per frame
        lat = lat.reshape(B, V, Hh + 1, self.z_dim, self.lat_h, self.lat_w).permute(0, 1, 3, 2, 4, 5)
        now = torch.ones(B, 1, dtype=torch.bool, device=batch.history_valid.device)  # the current frame
        known = torch.cat([batch.history_valid, now], dim=1).float()
        context = self._tile(lat) * known[:, None, :, None, None]  # invalid history → zero latents
        black = torch.zeros_like(batch.control[:, :1])
        clip = torch.cat([black, batch.control, batch.control[:, -1:].expand(-1, self.pad, -1, -1, -1)], dim=1)
        ctrl = self._encode(clip)[:, :, 1:]  # drop the black slot: n_f latents aligned with the future
        T = Hh + 1 + self.n_future
        cond = torch.zeros(B, 1 + self.z_dim, T, self.lat_h, V * self.lat_w, device=context.device)
        cond[:, 0, : Hh + 1] = known[:, :, None, None]
        cond[:, 1:, Hh + 1 :, :, : self.lat_w] = ctrl  # head view's tile only
        current = lat[:, :, :, -1:].reshape(B * V, self.z_dim, 1, self.lat_h, self.lat_w)
        return context, cond, current

    def predict_batch(self, batch: WorldModelBatch, *, steps: int | None = None, seed: int = 0) -> torch.Tensor:
        """uint8 ``[B, V, K, 3, H, W]``; same ``seed`` → identical output."""
        batch.check(self._info)
        steps = self.default_steps if steps is None else steps
        if isinstance(steps, bool) or not isinstance(steps, int) or steps < 1:
            raise ValueError(f"steps: expected an integer >= 1, got {steps!r}")
        B, V, K = batch.size, len(self._info.views), self._info.future
        n_ctx, dev, dtype = self._info.history + 1, self.device, self.transformer.dtype
        with torch.no_grad():
            batch = batch.to(dev)
            context, cond, current = self._conditioning(batch)
            text = self.text(batch.instruction).to(dtype)
            g = torch.Generator().manual_seed(seed)  # CPU generator: the same noise on every device
            shape = (B, self.z_dim, self.n_future, self.lat_h, V * self.lat_w)
            x = torch.randn(shape, generator=g).to(dev)
            scheduler = _diffusers().FlowMatchEulerDiscreteScheduler(shift=self.flow_shift)
            scheduler.set_timesteps(steps, device=dev)
            for t in scheduler.timesteps:
                per_frame = torch.cat([torch.zeros(n_ctx, device=dev), t.float().expand(self.n_future)])
                ts = per_frame.repeat_interleave(self.tokens_per_frame).expand(B, -1)  # frame-major token order
                hidden = torch.cat([torch.cat([context, x], dim=2), cond], dim=1).to(dtype)
                v = self.transformer(hidden, timestep=ts, encoder_hidden_states=text, return_dict=False)[0]
                x = scheduler.step(v[:, :, n_ctx:].float(), t, x, return_dict=False)[0]
            future = x.reshape(B, self.z_dim, self.n_future, self.lat_h, V, self.lat_w).permute(0, 4, 1, 2, 3, 5)
            future = future.reshape(B * V, self.z_dim, self.n_future, self.lat_h, self.lat_w)
            video = self._decode(torch.cat([current, future], dim=2))  # [B·V, 1 + K + pad, 3, H, W]
            out = video[:, 1 : 1 + K].reshape(B, V, K, 3, self._info.height, self._info.width)
        return out.cpu()

    def predict(
        self, request: PredictRequest, *, steps: int | None = None, seed: int = 0
    ) -> dict[str, NDArray[np.uint8]]:
        return predict_one(self, request, steps=steps, seed=seed)
