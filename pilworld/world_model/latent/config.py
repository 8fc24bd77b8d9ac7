"""Configuration of the native PiL-World model: sizes (presets), conditioning switches (ablations), sampling.

Presets are chosen by measurement (see ``docs/world_model.md``): ``tiny`` for tests (any image size
divisible by 16), ``small`` the CPU default for the simulated rig at 128×128, ``base`` for a GPU.
The ablation switches reproduce the paper-style comparison:

* ``history=False``          — no latent history memory (the paper's history ablation);
* ``control_video=False`` + ``action_tokens=True`` — per-frame raw-action tokens instead of the control
  video (a Ctrl-World-style baseline);
* ``control_video=True`` + ``action_tokens=True`` — both;
* success-only training data is a property of the training run (``success_fraction=1``), not the model.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field
from typing import Any

from pilworld.types import DEFAULT_VIEWS, STATE_DIM
from pilworld.world_model.base import WorldModelInfo


def _positive(name: str, value: Any) -> None:
    if isinstance(value, bool) or not isinstance(value, int) or value < 1:
        raise ValueError(f"{name}: expected an integer >= 1, got {value!r}")


@dataclass(frozen=True)
class VAEConfig:
    """The frame VAE E_φ / D_φ, shared across views: 8× spatial downsampling to ``latent_channels``."""

    channels: tuple[int, int] = (48, 96)  # widths at 1/4 and 1/8 resolution
    latent_channels: int = 8  # C of the latent grid (H/8 × W/8 × C)
    kl_weight: float = 1e-6  # a nearly deterministic autoencoder, as latent diffusion VAEs are

    def __post_init__(self) -> None:
        if len(self.channels) != 2:
            raise ValueError(f"vae.channels: expected two widths, got {self.channels!r}")
        for c in self.channels:
            _positive("vae.channels", c)
        _positive("vae.latent_channels", self.latent_channels)
        if self.kl_weight < 0:
            raise ValueError(f"vae.kl_weight: expected >= 0, got {self.kl_weight!r}")


@dataclass(frozen=True)
class DenoiserConfig:
    """Ψ_θ: a transformer over (view × spatial) tokens; the K future frames of a token sit on its channels."""

    width: int = 256  # d, token width
    depth: int = 6  # transformer blocks
    heads: int = 4  # attention heads
    mlp_ratio: float = 4.0
    patch: int = 2  # latent cells per token side (a token covers 8·patch pixels)
    control_channels: int = 8  # control-video stem output channels per frame (at latent resolution)
    text_buckets: int = 4096  # hashed word vocabulary of the instruction encoder
    text_width: int = 64

    def __post_init__(self) -> None:
        for name in ("width", "depth", "heads", "patch", "control_channels", "text_buckets", "text_width"):
            _positive(f"denoiser.{name}", getattr(self, name))
        if self.width % self.heads:
            raise ValueError(f"denoiser.width: {self.width} is not divisible by heads={self.heads}")
        if self.mlp_ratio <= 0:
            raise ValueError(f"denoiser.mlp_ratio: expected > 0, got {self.mlp_ratio!r}")


@dataclass(frozen=True)
class ConditioningConfig:
    """Which conditions Ψ_θ sees (the ablation switches) and the training-time augmentations."""

    history: bool = True  # latent history memory Z^h
    control_video: bool = True  # head-view control video C_t = Γ(A)
    action_tokens: bool = False  # per-frame raw stride-aligned action tokens (Ctrl-World style)
    history_dropout: float = 0.15  # chance per training sample of hiding the whole history (robust starts)
    condition_noise: float = 0.1  # max std of noise added to clean condition latents (DIAMOND's augmentation):
    # in closed loop the history and current frame are generated, so the model must tolerate their errors

    def __post_init__(self) -> None:
        if not (self.control_video or self.action_tokens):
            raise ValueError("conditioning: the model needs the control video, action tokens, or both")
        if not 0.0 <= self.history_dropout < 1.0:
            raise ValueError(f"conditioning.history_dropout: expected [0, 1), got {self.history_dropout!r}")
        if self.condition_noise < 0:
            raise ValueError(f"conditioning.condition_noise: expected >= 0, got {self.condition_noise!r}")


@dataclass(frozen=True)
class WorldModelConfig:
    """Everything needed to rebuild a native model (stored as JSON beside its safetensors)."""

    preset: str = "small"
    views: tuple[str, ...] = DEFAULT_VIEWS
    height: int = 128
    width: int = 128
    future: int = 15  # K
    history: int = 5  # H_h
    action_dim: int = STATE_DIM
    steps: int = 4  # default Euler steps at inference
    residual_gate: float = 0.1  # gated residual decoding width (see PilWorldModel.render_future); 0 = off
    parameterization: str = "residual_x0"  # or "velocity" (see PilWorldModel.velocity)
    pure_noise_fraction: float = 0.2  # training samples at τ = 1 (where sampling starts); the rest τ ~ U(0, 1)
    vae: VAEConfig = field(default_factory=VAEConfig)
    denoiser: DenoiserConfig = field(default_factory=DenoiserConfig)
    conditioning: ConditioningConfig = field(default_factory=ConditioningConfig)
    # Per-channel statistics of the VAE latents, set after the VAE is trained, so Ψ_θ sees unit-scale latents.
    latent_mean: tuple[float, ...] = ()
    latent_std: tuple[float, ...] = ()

    def __post_init__(self) -> None:
        info = self.info  # validates views, sizes, K, H_h
        cell = 8 * self.denoiser.patch
        if info.height % cell or info.width % cell:
            raise ValueError(
                f"image size: {info.width}x{info.height} must be divisible by {cell} "
                f"(8× VAE downsampling × token patch {self.denoiser.patch})"
            )
        _positive("steps", self.steps)
        if self.residual_gate < 0:
            raise ValueError(f"residual_gate: expected >= 0, got {self.residual_gate!r}")
        if not 0.0 <= self.pure_noise_fraction <= 1.0:
            raise ValueError(f"pure_noise_fraction: expected a value in [0, 1], got {self.pure_noise_fraction!r}")
        if self.parameterization not in ("residual_x0", "velocity"):
            raise ValueError(f"parameterization: expected 'residual_x0' or 'velocity', got {self.parameterization!r}")
        for name in ("latent_mean", "latent_std"):
            v = getattr(self, name)
            if v and len(v) != self.vae.latent_channels:
                raise ValueError(f"{name}: expected {self.vae.latent_channels} values, got {len(v)}")
        if any(s <= 0 for s in self.latent_std):
            raise ValueError(f"latent_std: expected positive values, got {self.latent_std!r}")

    @property
    def info(self) -> WorldModelInfo:
        return WorldModelInfo(self.views, self.height, self.width, self.future, self.history, self.action_dim)

    def replace(self, **changes: Any) -> WorldModelConfig:
        return dataclasses.replace(self, **changes)

    def to_dict(self) -> dict[str, Any]:
        return dataclasses.asdict(self)

    @classmethod
    def from_dict(cls, data: dict[str, Any]) -> WorldModelConfig:
        data = dict(data)
        if "residual_decoding" in data:  # configs written before the gate: on = the default gate width
            on = bool(data.pop("residual_decoding"))
            data.setdefault("residual_gate", cls.residual_gate if on else 0.0)
        known = {f.name for f in dataclasses.fields(cls)}
        unknown = sorted(set(data) - known)
        if unknown:
            raise ValueError(f"world-model config: unknown keys {unknown} (known: {sorted(known)})")
        d = dict(data)
        parts: dict[str, type] = {"vae": VAEConfig, "denoiser": DenoiserConfig, "conditioning": ConditioningConfig}
        for key, kind in parts.items():
            if key in d and isinstance(d[key], dict):
                sub_known = {f.name for f in dataclasses.fields(kind)}
                bad = sorted(set(d[key]) - sub_known)
                if bad:
                    raise ValueError(f"world-model config: unknown keys {bad} in {key!r} (known: {sorted(sub_known)})")
                sub = dict(d[key])
                if "channels" in sub:
                    sub["channels"] = tuple(sub["channels"])
                d[key] = kind(**sub)
        for key in ("views", "latent_mean", "latent_std"):
            if key in d:
                d[key] = tuple(d[key])
        return cls(**d)


PRESETS: dict[str, WorldModelConfig] = {
    # Tests: a fraction of a second per training step at 32×32.
    "tiny": WorldModelConfig(
        preset="tiny",
        height=32,
        width=32,
        vae=VAEConfig(channels=(16, 32), latent_channels=4),
        denoiser=DenoiserConfig(width=64, depth=2, heads=2, control_channels=4, text_buckets=256, text_width=16),
        steps=2,
    ),
    # The CPU default for the simulated rig at 128×128. One Euler step: on validation clips it scored the best
    # PSNR and SSIM of 1, 2, 4 and 8 steps, and is the fastest (docs/world_model.md).
    "small": WorldModelConfig(preset="small", steps=1),
    # For a GPU: twice the width, twice the depth, a wider VAE.
    "base": WorldModelConfig(
        preset="base",
        vae=VAEConfig(channels=(96, 192), latent_channels=8),
        denoiser=DenoiserConfig(width=512, depth=12, heads=8, control_channels=16),
    ),
}


def preset(name: str, **changes: Any) -> WorldModelConfig:
    """A preset by name, with top-level fields replaced (e.g. ``height=64``)."""
    if name not in PRESETS:
        raise ValueError(f"preset: unknown {name!r}; known presets: {sorted(PRESETS)}")
    return PRESETS[name].replace(**changes) if changes else PRESETS[name]
