"""The learned part of world model v2: a small U-Net that composites candidate layers.

Input per (view, future frame), at the network's working resolution: the candidate layers of
:mod:`.layers` (static prior, the current frame, what each hand carries), the robot render (part ids
one-hot, shade, depth), per-frame flags (holding / released per arm, k/K) and the view. Output:

* per-pixel gate logits over the candidates ``[prior, carry_left, carry_right, generated, plate]``
  (``plate``: the static head camera's empty scene, a buffer estimated from the training data; ``memory``:
  what the head camera last saw of each pixel without the robot over it);
* ``generated``: an RGB fill for what no layer has (disoccluded table, a shadow);
* the gripper openings (left, right) the robot will *measure* at that frame (a gripper closed on an
  object stops at its width), from the bottleneck features.

The robot's own pixels are painted by a per-pixel map from its render (:class:`RobotPainter`), at
full resolution, and composited with the render's exact mask; nothing of the robot is left to the gates.
"""

from __future__ import annotations

import torch
from torch import nn
from torch.nn import functional as F

N_PARTS = 5  # background, left arm, left fingers, right arm, right fingers
# The current frame is an input, not a candidate: outside the robot's pixels it equals the prior, and on
# them it shows the robot where it no longer is (a ghost). "plate": the empty scene of a static camera.
CANDIDATES = ("prior", "carry_left", "carry_right", "generated", "plate", "memory")
N_VIEWS = 3
# prior 3 + valid 1, current 3, carry L 3 + 1, carry R 3 + 1, parts one-hot 4, shade 1, depth 1,
# memory 3 + valid 1, hand region 1, flags: holding L/R, released L/R, k/K (5), view one-hot 3, commanded grips L/R 2
IN_CHANNELS = 4 + 3 + 4 + 4 + 4 + 1 + 1 + 4 + 1 + 5 + N_VIEWS + 2


def _conv(cin: int, cout: int) -> nn.Sequential:
    return nn.Sequential(nn.Conv2d(cin, cout, 3, padding=1), nn.GroupNorm(4, cout), nn.SiLU())


class CompositeUNet(nn.Module):
    """Three-level U-Net at ``work`` pixels: widths ``(w, 2w, 3w)`` at 1, ½ and ¼ of it.

    Inputs at any multiple of ``work`` are area-averaged to it first; the outputs are at ``work``
    (the composite upsamples the gates: they choose between sharp full-resolution layers).
    """

    def __init__(self, width: int = 16, work: int = 32, extra: int = 0) -> None:
        super().__init__()
        w1, w2, w3 = width, 2 * width, 3 * width
        self.work = work
        self.in_channels = IN_CHANNELS + extra  # extra: a variant's marker or action-token planes (switches.py)
        self.stem = _conv(self.in_channels, w1)
        self.enc2 = nn.Sequential(_conv(w1, w2), _conv(w2, w2))
        self.enc3 = nn.Sequential(_conv(w2, w3), _conv(w3, w3))
        self.dec2 = _conv(w3 + w2, w2)
        self.dec1 = _conv(w2 + w1, w1)
        self.head = nn.Conv2d(w1, len(CANDIDATES) + 3, 3, padding=1)
        self.grip = nn.Sequential(nn.Linear(w3 + 2, 64), nn.SiLU(), nn.Linear(64, 2))
        with torch.no_grad():  # start by trusting the static prior: the scene mostly stays where it is
            bias = self.head.bias
            assert bias is not None
            self.head.weight.mul_(0.1)
            bias.zero_()
            bias[0] = 2.0

    def forward(self, x: torch.Tensor, commanded_grip: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
        """x (N, in_channels, h, w) in [0, 1] → (gate logits (N, 5, s, s), generated RGB (N, 3, s, s), grips (N, 2))."""
        if x.shape[-1] != self.work:
            x = F.adaptive_avg_pool2d(x, self.work)
        e1 = self.stem(x)
        e2 = self.enc2(F.avg_pool2d(e1, 2))
        e3 = self.enc3(F.avg_pool2d(e2, 2))
        d2 = self.dec2(torch.cat([F.interpolate(e3, scale_factor=2.0, mode="nearest"), e2], 1))
        d1 = self.dec1(torch.cat([F.interpolate(d2, scale_factor=2.0, mode="nearest"), e1], 1))
        out = self.head(d1)
        gates = out[:, : len(CANDIDATES)]
        generated = torch.sigmoid(out[:, len(CANDIDATES) :])
        pooled = e3.mean(dim=(2, 3))
        grips = commanded_grip + self.grip(torch.cat([pooled, commanded_grip], 1))  # a correction of the command
        return gates, generated, grips


class RobotPainter(nn.Module):
    """The robot's colour at a pixel from its render there: part one-hot, shade, depth, view (a per-pixel MLP).

    Applied only where the render has robot, so it costs in proportion to the robot's pixels. At inference
    the render is exact (one part per pixel, shade and depth quantised to bytes), so :meth:`paint_points`
    looks the colour up in a table of every (view, part, shade, depth), the MLP evaluated once per weights.
    """

    def __init__(self, hidden: int = 32) -> None:
        super().__init__()
        self.net = nn.Sequential(
            nn.Linear(N_VIEWS + (N_PARTS - 1) + 2, hidden),
            nn.SiLU(),
            nn.Linear(hidden, hidden),
            nn.SiLU(),
            nn.Linear(hidden, 3),
        )
        self._table: torch.Tensor | None = None
        self._table_key: tuple[int, ...] = ()

    @torch.no_grad()
    def table(self) -> torch.Tensor:
        """(views · parts · 256 · 256, 3) colours for every byte-quantised input, rebuilt when the weights change."""
        key = tuple(p.data_ptr() for p in self.parameters()) + tuple(p._version for p in self.parameters())
        if self._table is None or key != self._table_key:
            level = torch.arange(256, dtype=torch.float32) / 255.0
            v, p, s, d = torch.meshgrid(
                torch.arange(N_VIEWS), torch.arange(N_PARTS - 1), torch.arange(256), torch.arange(256), indexing="ij"
            )
            x = torch.cat(
                [
                    F.one_hot(p.reshape(-1), N_PARTS - 1).float(),
                    level[s.reshape(-1)][:, None],
                    level[d.reshape(-1)][:, None],
                    F.one_hot(v.reshape(-1), N_VIEWS).float(),
                ],
                1,
            )
            self._table = torch.sigmoid(self.net(x))
            self._table_key = key
        return self._table

    def paint_points(
        self, part_ids: torch.Tensor, shade: torch.Tensor, depth: torch.Tensor, view: torch.Tensor
    ) -> torch.Tensor:
        """The robot's colour at given pixels from the table: part ids in 1 … 4, uint8 shade and depth, view,
        each (P,) → RGB (P, 3) in [0, 1]."""
        index = (view.long() * (N_PARTS - 1) + part_ids.long() - 1) * 256 + shade.long()
        return self.table()[index * 256 + depth.long()]

    def forward(
        self, parts_onehot: torch.Tensor, shade: torch.Tensor, depth: torch.Tensor, view: torch.Tensor
    ) -> torch.Tensor:
        """(N, 4, h, w), (N, 1, h, w), (N, 1, h, w), view index (N,) → RGB (N, 3, h, w) in [0, 1], 0 off the robot."""
        n, _, h, w = parts_onehot.shape
        feats = torch.cat([parts_onehot, shade, depth], 1).permute(0, 2, 3, 1)  # (N, h, w, 6)
        on = parts_onehot.sum(1) > 0  # (N, h, w)
        out = torch.zeros(n, h, w, 3, dtype=feats.dtype)
        if on.any():
            views = F.one_hot(view.long(), N_VIEWS).to(feats.dtype)[:, None, None].expand(n, h, w, N_VIEWS)
            x = torch.cat([feats[on], views[on]], 1)
            out[on] = torch.sigmoid(self.net(x))
        return out.permute(0, 3, 1, 2)
