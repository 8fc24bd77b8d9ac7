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
KEYPOINTS = 16  # spatial-softmax keypoints per view (arch "keypoints")
ARCHS = ("grid", "keypoints")


def _block(cin: int, cout: int) -> nn.Sequential:
    return nn.Sequential(nn.Conv2d(cin, cout, 3, 2, 1), nn.SiLU())


class SpatialSoftmax(nn.Module):
    """(N, K, H, W) feature maps → (N, 3·K): each map's expected x and y under its softmax, and its peak.

    Where a feature fires, as coordinates (Levine et al., "End-to-End Training of Deep Visuomotor
    Policies", 2016): "the object ended up in the bowl" becomes a relation between two points that a small
    head learns from few examples wherever the scene puts them, which a flattened grid must learn per cell.
    """

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        N, K, H, W = x.shape
        flat = x.flatten(2)
        prob = flat.softmax(-1).view(N, K, H, W)
        ys = torch.linspace(-1, 1, H, device=x.device)
        xs = torch.linspace(-1, 1, W, device=x.device)
        ex = (prob.sum(2) * xs).sum(-1)
        ey = (prob.sum(3) * ys).sum(-1)
        return torch.cat([ex, ey, flat.amax(-1)], dim=1)


class JudgeNet(nn.Module):
    """Inputs: frames (B, V, 6, S, S) in [0, 1], state (B, 2·D), context (B, CONTEXT_DIM). Output: (B,) logits."""

    state_mean: torch.Tensor
    state_std: torch.Tensor

    def __init__(
        self, n_views: int, state_dim: int, side: int, width: int = WIDTH, dropout: float = 0.3, arch: str = "grid"
    ) -> None:
        super().__init__()
        if side % 16:
            raise ValueError(f"side: expected a multiple of 16, got {side}")
        if arch not in ARCHS:
            raise ValueError(f"arch: expected one of {', '.join(ARCHS)}, got {arch!r}")
        w2 = 2 * width
        if arch == "grid":  # four stride-2 convolutions to a (side/16)² grid, flattened
            self.trunk = nn.Sequential(_block(6, width), _block(width, w2), _block(w2, w2), _block(w2, w2))
            n_feat = w2 * (side // 16) ** 2
        else:  # two stride-2 convolutions to (side/4)², one more at that size, keypoints
            self.trunk = nn.Sequential(
                _block(6, width),
                _block(width, w2),
                nn.Conv2d(w2, w2, 3, 1, 1),
                nn.SiLU(),
                nn.Conv2d(w2, KEYPOINTS, 1),
                SpatialSoftmax(),
            )
            n_feat = 3 * KEYPOINTS
        self.views = nn.ModuleList(nn.Linear(n_feat, EMBED) for _ in range(n_views))
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
