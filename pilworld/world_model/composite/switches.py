"""What a world-model v2 variant keeps of the shipped recipe: the equal-budget table's switches
(docs/RESULTS.md, section 1).

Every variant is trained by the same command on the same sample cache (same clips, frames, steps, batch,
seed, network size); only these switches differ. They act on the cached base channels (:mod:`.cache`), so
one cache serves every variant, and the same function applies them at training and at inference:

* ``control`` — which control video the network sees:

  - ``render+prior`` (shipped): Γ⁺'s robot render (part ids, shade, depth) and its scene reprojection prior;
  - ``render``: the render, no reprojection: the static candidate is the *current frame unwarped* (the robot
    where it is now included, as a video model that copies its context would have it);
  - ``markers``: the paper's Γ — one marker and trace per gripper in the head view, nothing in the wrist views
    — and no render; the static candidate is the current frame;
  - ``none``: no control video at all (the Ctrl-World-style baseline, with ``action_tokens``).

* ``paste`` — the robot painted from its render under the render's exact mask (shipped) instead of left to
  the gated blend (a soft control: the render is only an input). Needs a render.
* ``history`` — the head view's memory layer (each pixel as last seen without the robot over it, over the
  last round of history frames). Off: hidden in training and inference.
* ``hands`` — outside the region near the tools' paths nothing moves (shipped). Off: the gates decide at
  every pixel.
* ``action_tokens`` — the chunk's commanded action at each frame (14 numbers) as extra input planes, the way
  Ctrl-World conditions its video model on per-frame action tokens.

The tracked objects and the predicted state are the same in every variant (they have no learned weights);
the data switch (success-only clips) lives in the training settings, since it changes no network input.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass
from typing import Any, Final

import numpy as np
import torch

from pilworld.world_model.composite.cache import GRIPS

CONTROLS: Final = ("render+prior", "render", "markers", "none")
MARKER_CHANNELS: Final = 3
TOKEN_CHANNELS: Final = 14
JOINT_SCALE: Final = float(np.pi)  # joint angles are divided by this for the token planes (grips stay in [0, 1])

# Base channel groups (cache.chunk_channels): prior 0-2 + valid 3, current 4-6, render 15-20, memory 21-24, hands 25
_PRIOR, _PRIOR_VALID, _CURRENT = slice(0, 3), 3, slice(4, 7)
_RENDER, _MEMORY, _HANDS = slice(15, 21), slice(21, 25), 25


@dataclass(frozen=True)
class Switches:
    """The parts of v2's recipe a variant keeps (the defaults are the shipped model)."""

    control: str = "render+prior"
    paste: bool = True
    history: bool = True
    hands: bool = True
    action_tokens: bool = False

    def __post_init__(self) -> None:
        if self.control not in CONTROLS:
            raise ValueError(f"control: expected one of {', '.join(CONTROLS)}, got {self.control!r}")
        if self.paste and not self.render:
            raise ValueError(f"paste: the robot is pasted from its render, and control {self.control!r} has none")
        for name in ("paste", "history", "hands", "action_tokens"):
            if not isinstance(getattr(self, name), bool):
                raise ValueError(f"{name}: expected true or false, got {getattr(self, name)!r}")

    @property
    def render(self) -> bool:
        return self.control.startswith("render")

    @property
    def prior(self) -> bool:
        return self.control == "render+prior"

    @property
    def markers(self) -> bool:
        return self.control == "markers"

    @property
    def shipped(self) -> bool:
        return self == Switches()

    @property
    def extra_channels(self) -> int:
        """Input planes beyond the shipped network's (markers, action tokens)."""
        return MARKER_CHANNELS * self.markers + TOKEN_CHANNELS * self.action_tokens

    @property
    def needs_extras(self) -> bool:
        """Training needs the cache's per-sample markers and actions (:func:`.cache.build_extras`)."""
        return self.markers or self.action_tokens

    def describe(self) -> str:
        if self.shipped:
            return "shipped v2"
        off = [n for n in ("paste", "history", "hands") if not getattr(self, n)]
        parts = [f"control {self.control}"] + [f"no {n}" for n in off]
        if self.action_tokens:
            parts.append("action tokens")
        return ", ".join(parts)

    def to_dict(self) -> dict[str, Any]:
        return asdict(self)

    @classmethod
    def from_dict(cls, d: dict[str, Any] | None) -> Switches:
        if not d:
            return cls()
        unknown = sorted(set(d) - set(cls.__dataclass_fields__))
        if unknown:
            raise ValueError(f"switches: unknown keys {unknown}; expected {sorted(cls.__dataclass_fields__)}")
        return cls(**d)

    def apply(self, base: torch.Tensor) -> torch.Tensor:
        """The base channels (N, 26, h, w), uint8 or float in [0, 255], as this variant sees them.

        The shipped switches return ``base`` itself (no copy); any other returns a modified copy.
        """
        if self.shipped:
            return base
        x = base.clone()
        top = 255 if x.dtype == torch.uint8 else 255.0
        if not self.prior:  # the static candidate is the current frame as it is, valid everywhere
            x[:, _PRIOR] = x[:, _CURRENT]
            x[:, _PRIOR_VALID] = top
        if not self.render:
            x[:, _RENDER] = 0
        if not self.history:
            x[:, _MEMORY] = 0
        if not self.hands:
            x[:, _HANDS] = top
        return x


def token_planes(actions: torch.Tensor) -> torch.Tensor:
    """(N, 14) commanded actions → (N, 14) token values: joints / π, grips as they are."""
    t = actions.float() / JOINT_SCALE
    t[:, GRIPS] = actions[:, GRIPS].float()
    return t
