"""The instruction encoder: a learned embedding of hashed words (offline, any string, no downloaded model).

The paper feeds the instruction g through Wan's T5 encoder. Our tasks are few and their instructions
short, so a learned bag of hashed words is enough and keeps the model self-contained: any string
encodes (unseen words land in some bucket), nothing is fetched at run time, and the mapping is a
stable hash (CRC-32), so it is the same on every machine and Python version.
"""

from __future__ import annotations

import itertools
import re
import zlib
from collections.abc import Sequence

import torch
from torch import nn

_WORD = re.compile(r"[a-z0-9]+")


def word_buckets(text: str, buckets: int) -> list[int]:
    """Bucket ids of the lower-cased words and word pairs of ``text`` (pairs keep a little word order)."""
    words = _WORD.findall(text.lower())
    grams = words + [f"{a} {b}" for a, b in itertools.pairwise(words)]
    return [zlib.crc32(g.encode()) % buckets for g in grams] or [0]


class InstructionEncoder(nn.Module):
    """Strings → [B, out_width] vectors (mean of hashed word embeddings, then an MLP)."""

    def __init__(self, buckets: int, width: int, out_width: int) -> None:
        super().__init__()
        self.buckets = buckets
        self.embed = nn.EmbeddingBag(buckets, width, mode="mean")
        self.mlp = nn.Sequential(nn.Linear(width, out_width), nn.SiLU(), nn.Linear(out_width, out_width))

    def forward(self, texts: Sequence[str]) -> torch.Tensor:
        ids: list[int] = []
        offsets: list[int] = []
        for t in texts:
            offsets.append(len(ids))
            ids.extend(word_buckets(t, self.buckets))
        device = self.embed.weight.device
        out: torch.Tensor = self.mlp(
            self.embed(torch.tensor(ids, dtype=torch.long, device=device), torch.tensor(offsets, device=device))
        )
        return out
