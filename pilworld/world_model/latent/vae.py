"""The frame VAE E_φ / D_φ (paper §3.2), shared across views: images [N, 3, H, W] ↔ latents [N, C, H/8, W/8].

Sized for the CPU: the decoder turns 45 latent frames (K = 15 × 3 views) back into 128×128 images in a
few tens of milliseconds (see :class:`FrameVAE`).
"""

from __future__ import annotations

import torch
from torch import nn
from torch.nn import functional as F

from pilworld.world_model.latent.config import VAEConfig


def _groups(channels: int) -> int:
    return 8 if channels % 8 == 0 else 1


class ResBlock(nn.Module):
    def __init__(self, channels: int) -> None:
        super().__init__()
        self.norm1 = nn.GroupNorm(_groups(channels), channels)
        self.conv1 = nn.Conv2d(channels, channels, 3, padding=1)
        self.norm2 = nn.GroupNorm(_groups(channels), channels)
        self.conv2 = nn.Conv2d(channels, channels, 3, padding=1)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        h = self.conv1(F.silu(self.norm1(x)))
        out: torch.Tensor = x + self.conv2(F.silu(self.norm2(h)))
        return out


class FrameVAE(nn.Module):
    """Encoder to a diagonal Gaussian over latents; decoder back to images in [−1, 1].

    Both ends work at 1/4 resolution at most: the encoder starts with a 4× space-to-depth (pixel
    unshuffle) and the decoder ends with a 4× depth-to-space (pixel shuffle). Measured on 2 CPU cores,
    this decodes K·V = 45 frames at 128×128 in ~25 ms where full-resolution convolutions took ~160 ms.
    """

    def __init__(self, config: VAEConfig) -> None:
        super().__init__()
        c2, c3 = config.channels
        z = config.latent_channels
        self.config = config
        self.encoder = nn.Sequential(
            nn.PixelUnshuffle(4),  # [3, H, W] -> [48, H/4, W/4]
            nn.Conv2d(48, c2, 3, padding=1),
            ResBlock(c2),
            nn.Conv2d(c2, c3, 4, stride=2, padding=1),  # 1/8
            ResBlock(c3),
            nn.GroupNorm(_groups(c3), c3),
            nn.SiLU(),
            nn.Conv2d(c3, 2 * z, 1),
        )
        self.decoder = nn.Sequential(
            nn.Conv2d(z, c3, 3, padding=1),
            ResBlock(c3),
            nn.Conv2d(c3, 4 * c2, 1),
            nn.PixelShuffle(2),  # 1/4
            ResBlock(c2),
            nn.GroupNorm(_groups(c2), c2),
            nn.SiLU(),
            nn.Conv2d(c2, 48, 3, padding=1),
            nn.PixelShuffle(4),  # full resolution
        )

    def encode(self, x: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """Images [N, 3, H, W] in [−1, 1] → (mean, logvar), each [N, C, H/8, W/8]."""
        mean, logvar = self.encoder(x).chunk(2, dim=1)
        return mean, logvar.clamp(-30.0, 20.0)

    def decode(self, z: torch.Tensor) -> torch.Tensor:
        """Latents [N, C, h, w] → images [N, 3, 8h, 8w] (unbounded; clamp to [−1, 1] for display)."""
        out: torch.Tensor = self.decoder(z)
        return out

    def loss(self, x: torch.Tensor, generator: torch.Generator | None = None) -> tuple[torch.Tensor, dict[str, float]]:
        """Reconstruction (L1 + MSE, which PSNR rewards) plus a small KL term."""
        mean, logvar = self.encode(x)
        eps = torch.randn(mean.shape, generator=generator, dtype=mean.dtype, device=mean.device)
        z = mean + torch.exp(0.5 * logvar) * eps
        rec = self.decode(z)
        l1 = (rec - x).abs().mean()
        mse = ((rec - x) ** 2).mean()
        kl = 0.5 * (mean**2 + logvar.exp() - 1.0 - logvar).mean()
        total = l1 + mse + self.config.kl_weight * kl
        psnr = 10.0 * torch.log10(4.0 / mse.detach().clamp_min(1e-10))  # range [−1, 1] → peak² = 4
        return total, {
            "loss": float(total.detach()),
            "l1": float(l1.detach()),
            "kl": float(kl.detach()),
            "psnr": float(psnr),
        }


def to_unit(x: torch.Tensor) -> torch.Tensor:
    """uint8 images → float in [−1, 1]."""
    return x.float().div(127.5).sub(1.0)


def to_uint8(x: torch.Tensor) -> torch.Tensor:
    """Float images in [−1, 1] → uint8."""
    return x.add(1.0).mul(127.5).round().clamp(0, 255).to(torch.uint8)
