"""Ψ_θ: denoises the future latents Z^f of all views jointly, in one pass (paper §3.2, appendix "Latent
Training Objective").

Tokens are (view, spatial cell) pairs: a cell of ``patch × patch`` latents, with the **K future frames
stacked on its channels** (DIAMOND stacks frames on channels too). This keeps the sequence short
(3 views × 64 cells at 128×128) so full attention across views and cells is cheap on a CPU, and every
token sees every view: cross-view consistency comes from attention, view identity from a learned view
embedding. Each token also carries, on its channels, the clean current-frame latents Z⁰ and the
history latents Z^h of its cell (flagged valid or missing), and head-view tokens add the control video
C_t encoded by a small convolutional stem. The noise level and the instruction g modulate every block
(adaLN-Zero, as in DiT). The action-token ablation appends one token per stride-aligned action.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import torch
from torch import nn
from torch.nn import functional as F

from pilworld.types import HEAD_VIEW
from pilworld.world_model.latent.config import WorldModelConfig
from pilworld.world_model.latent.text import InstructionEncoder

# peft's LoRA targets (stage-2 fine-tuning): the attention and MLP projections of every block.
LORA_TARGETS = ("qkv", "proj", "fc1", "fc2")


def timestep_embedding(tau: torch.Tensor, dim: int) -> torch.Tensor:
    """Sinusoidal embedding of the noise level τ ∈ [0, 1] → [B, dim]."""
    half = dim // 2
    freqs = torch.exp(-math.log(10_000.0) * torch.arange(half, device=tau.device, dtype=torch.float32) / half)
    args = (tau.float() * 1000.0)[:, None] * freqs[None]
    return torch.cat([torch.cos(args), torch.sin(args)], dim=-1)


class Block(nn.Module):
    def __init__(self, width: int, heads: int, mlp_ratio: float) -> None:
        super().__init__()
        self.heads = heads
        self.norm1 = nn.LayerNorm(width, elementwise_affine=False, eps=1e-6)
        self.qkv = nn.Linear(width, 3 * width)
        self.proj = nn.Linear(width, width)
        self.norm2 = nn.LayerNorm(width, elementwise_affine=False, eps=1e-6)
        hidden = int(width * mlp_ratio)
        self.fc1 = nn.Linear(width, hidden)
        self.fc2 = nn.Linear(hidden, width)
        self.modulation = nn.Linear(width, 6 * width)
        nn.init.zeros_(self.modulation.weight)
        nn.init.zeros_(self.modulation.bias)

    def forward(self, x: torch.Tensor, c: torch.Tensor) -> torch.Tensor:
        """x [B, N, d], c [B, d]."""
        B, N, d = x.shape
        shift1, scale1, gate1, shift2, scale2, gate2 = self.modulation(F.silu(c))[:, None].chunk(6, dim=-1)
        h = self.norm1(x) * (1 + scale1) + shift1
        q, k, v = self.qkv(h).reshape(B, N, 3, self.heads, d // self.heads).permute(2, 0, 3, 1, 4)
        a = F.scaled_dot_product_attention(q, k, v).transpose(1, 2).reshape(B, N, d)
        x = x + gate1 * self.proj(a)
        h = self.norm2(x) * (1 + scale2) + shift2
        out: torch.Tensor = x + gate2 * self.fc2(F.gelu(self.fc1(h), approximate="tanh"))
        return out


class ControlStem(nn.Module):
    """Control frames [M, 3, H, W] in [−1, 1] → features [M, C_c, H/8, W/8] (the latent grid)."""

    def __init__(self, out_channels: int) -> None:
        super().__init__()
        self.net = nn.Sequential(
            nn.Conv2d(3, 16, 4, stride=2, padding=1),
            nn.SiLU(),
            nn.Conv2d(16, 32, 4, stride=2, padding=1),
            nn.SiLU(),
            nn.Conv2d(32, out_channels, 4, stride=2, padding=1),
        )

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        out: torch.Tensor = self.net(x)
        return out


def patchify(x: torch.Tensor, p: int) -> torch.Tensor:
    """[B, *, C, h, w] → [B, (h/p)(w/p), (* · C · p · p)] (all leading-after-B dims go on channels)."""
    B = x.shape[0]
    x = x.reshape(B, -1, x.shape[-2], x.shape[-1])  # [B, F, h, w]
    Fc, h, w = x.shape[1:]
    x = x.reshape(B, Fc, h // p, p, w // p, p).permute(0, 2, 4, 1, 3, 5)
    return x.reshape(B, (h // p) * (w // p), Fc * p * p)


def unpatchify(tokens: torch.Tensor, p: int, h: int, w: int, lead: Sequence[int]) -> torch.Tensor:
    """Inverse of :func:`patchify`: [B, N, F·p·p] → [B, *lead, h, w] with prod(lead) = F."""
    B, _, D = tokens.shape
    Fc = D // (p * p)
    x = tokens.reshape(B, h // p, w // p, Fc, p, p).permute(0, 3, 1, 4, 2, 5)
    return x.reshape(B, *lead, h, w)


class Denoiser(nn.Module):
    """Ψ_θ(Z^f_τ, τ | Z⁰, Z^h, C_t, g) → velocity for Z^f, all views in one pass."""

    def __init__(self, config: WorldModelConfig) -> None:
        super().__init__()
        dc, cond = config.denoiser, config.conditioning
        self.config = config
        C, p, K, Hh, d = config.vae.latent_channels, dc.patch, config.future, config.history, dc.width
        self.h, self.w = config.height // 8, config.width // 8
        self.cells = (self.h // p) * (self.w // p)
        V = len(config.views)
        self.head_index = config.views.index(HEAD_VIEW) if HEAD_VIEW in config.views else 0
        cell = C * p * p
        in_width = (K + 1) * cell + (Hh * cell + Hh if cond.history else 0)
        self.token_in = nn.Linear(in_width, d)
        self.pos = nn.Parameter(torch.randn(1, 1, self.cells, d) * 0.02)
        self.view = nn.Parameter(torch.randn(1, V, 1, d) * 0.02)
        if cond.control_video:
            self.control_stem = ControlStem(dc.control_channels)
            self.control_in = nn.Linear(K * dc.control_channels * p * p, d)
        if cond.action_tokens:
            self.action_in = nn.Sequential(nn.Linear(config.action_dim, d), nn.SiLU(), nn.Linear(d, d))
            self.action_pos = nn.Parameter(torch.randn(1, K, d) * 0.02)
        self.time = nn.Sequential(nn.Linear(d, d), nn.SiLU(), nn.Linear(d, d))
        self.text = InstructionEncoder(dc.text_buckets, dc.text_width, d)
        self.blocks = nn.ModuleList([Block(d, dc.heads, dc.mlp_ratio) for _ in range(dc.depth)])
        self.norm_out = nn.LayerNorm(d, elementwise_affine=False, eps=1e-6)
        self.modulation_out = nn.Linear(d, 2 * d)
        self.token_out = nn.Linear(d, K * cell)
        for layer in (self.modulation_out, self.token_out):
            nn.init.zeros_(layer.weight)
            nn.init.zeros_(layer.bias)

    def condition_vector(self, tau: torch.Tensor, instruction: Sequence[str]) -> torch.Tensor:
        d = self.config.denoiser.width
        out: torch.Tensor = self.time(timestep_embedding(tau, d)) + self.text(instruction)
        return out

    def control_tokens(self, control: torch.Tensor) -> torch.Tensor:
        """Control video [B, K, 3, H, W] in [−1, 1] → per-cell tokens [B, cells, d] (computed once per call)."""
        B, K = control.shape[:2]
        feats = self.control_stem(control.flatten(0, 1))  # [B·K, C_c, h, w]
        feats = feats.reshape(B, K, *feats.shape[1:])
        out: torch.Tensor = self.control_in(patchify(feats, self.config.denoiser.patch))
        return out

    def forward(
        self,
        noisy: torch.Tensor,  # [B, V, K, C, h, w]
        tau: torch.Tensor,  # [B]
        current: torch.Tensor,  # [B, V, C, h, w]
        history: torch.Tensor | None,  # [B, V, H_h, C, h, w] (zeros where invalid)
        history_valid: torch.Tensor | None,  # [B, H_h] float 0/1
        control: torch.Tensor | None,  # [B, cells, d] from control_tokens
        actions: torch.Tensor | None,  # [B, K, A]
        instruction: Sequence[str],
        cond_vector: torch.Tensor | None = None,  # reuse across sampling steps when τ is shared
    ) -> torch.Tensor:
        cfg = self.config
        p = cfg.denoiser.patch
        B, V, K, C = noisy.shape[:4]
        per_view = []
        for v in range(V):
            parts = [patchify(noisy[:, v], p), patchify(current[:, v], p)]
            if cfg.conditioning.history:
                assert history is not None and history_valid is not None
                parts.append(patchify(history[:, v], p))
                parts.append(history_valid[:, None, :].expand(B, self.cells, -1).to(noisy.dtype))
            per_view.append(torch.cat(parts, dim=-1))
        x = self.token_in(torch.stack(per_view, dim=1)) + self.pos + self.view  # [B, V, cells, d]
        if cfg.conditioning.control_video:
            assert control is not None
            x[:, self.head_index] = x[:, self.head_index] + control
        x = x.reshape(B, V * self.cells, -1)
        if cfg.conditioning.action_tokens:
            assert actions is not None
            x = torch.cat([x, self.action_in(actions) + self.action_pos], dim=1)
        c = self.condition_vector(tau, instruction) if cond_vector is None else cond_vector
        for block in self.blocks:
            x = block(x, c)
        shift, scale = self.modulation_out(F.silu(c))[:, None].chunk(2, dim=-1)
        x = self.norm_out(x[:, : V * self.cells]) * (1 + scale) + shift
        out = self.token_out(x).reshape(B * V, self.cells, -1)
        return unpatchify(out, p, self.h, self.w, (K, C)).reshape(B, V, K, C, self.h, self.w)
