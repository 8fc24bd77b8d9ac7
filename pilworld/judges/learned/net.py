"""The learned success judge's network: a small convolutional encoder per view, state and context, one logit.

Sized for a few hundred labelled episodes on a CPU (~0.1 M parameters at the default width, ~0.05 s per
training step of 32 episodes on 2 cores): one convolutional trunk of four stride-2 convolutions, shared by
all views, reads each view's (first, last) frame pair down to a 4 × 4 grid (no normalisation layers: at
this size they cost more time than they gain),
which a per-view linear layer flattens — where something ended up matters, so the grid is not pooled
away. The state (first and last, normalised by the training set's statistics) and the context (the
instruction's hashed words, the subtask index) join before a two-layer head with dropout.
"""

from __future__ import annotations

import torch
from torch import nn

from pilworld.judges.learned.inputs import CONTEXT_DIM

WIDTH = 16  # channels of the first convolution; the trunk doubles them once
EMBED = 48  # each view's, the state's and the context's embedding


def _block(cin: int, cout: int) -> nn.Sequential:
    return nn.Sequential(nn.Conv2d(cin, cout, 3, 2, 1), nn.SiLU())


class JudgeNet(nn.Module):
    """Inputs: frames (B, V, 6, S, S) in [0, 1], state (B, 2·D), context (B, CONTEXT_DIM). Output: (B,) logits."""

    state_mean: torch.Tensor
    state_std: torch.Tensor

    def __init__(self, n_views: int, state_dim: int, side: int, width: int = WIDTH, dropout: float = 0.3) -> None:
        super().__init__()
        if side % 16:
            raise ValueError(f"side: expected a multiple of 16, got {side}")
        w2 = 2 * width
        self.trunk = nn.Sequential(_block(6, width), _block(width, w2), _block(w2, w2), _block(w2, w2))
        grid = (side // 16) ** 2
        self.views = nn.ModuleList(nn.Linear(w2 * grid, EMBED) for _ in range(n_views))
        self.state = nn.Sequential(nn.Linear(2 * state_dim, EMBED), nn.SiLU())
        self.context = nn.Linear(CONTEXT_DIM, EMBED)
        self.head = nn.Sequential(
            nn.Dropout(dropout),
            nn.Linear(EMBED * (n_views + 2), 2 * EMBED),
            nn.SiLU(),
            nn.Dropout(dropout),
            nn.Linear(2 * EMBED, 1),
        )
        self.register_buffer("state_mean", torch.zeros(2 * state_dim))
        self.register_buffer("state_std", torch.ones(2 * state_dim))

    def forward(self, frames: torch.Tensor, state: torch.Tensor, context: torch.Tensor) -> torch.Tensor:
        B, V = frames.shape[:2]
        feats = self.trunk(frames.flatten(0, 1) * 2 - 1).flatten(1).view(B, V, -1)
        parts = [proj(feats[:, i]) for i, proj in enumerate(self.views)]
        parts.append(self.state((state - self.state_mean) / self.state_std))
        parts.append(self.context(context))
        out: torch.Tensor = self.head(torch.cat(parts, dim=1)).squeeze(1)
        return out
