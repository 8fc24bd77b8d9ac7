"""Control-video styles: which of Γ⁺'s parts a control video carries.

A style is a ``+``-joined set of components:

* ``markers`` — the paper's Γ: one marker per gripper in the head view (unchanged, byte for byte, so
  the paper-faithful model stays reproducible); the wrist views carry nothing;
* ``render`` — the robot rendered from its own model in every view (part ids, depth, shaded image);
* ``prior`` — the scene reprojection prior: each view's current frame warped into its future camera poses
  through the table plane (needs the current frames and state).

Names are canonical in the order render, markers, prior (``markers+render`` parses as ``render+markers``).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Final

COMPONENTS: Final = ("render", "markers", "prior")
#: The styles offered on the command line (every non-empty combination, canonical names).
STYLES: Final = (
    "markers",
    "render",
    "render+markers",
    "prior",
    "render+prior",
    "markers+prior",
    "render+markers+prior",
)


@dataclass(frozen=True)
class Style:
    """A parsed style: which components are drawn."""

    render: bool
    markers: bool
    prior: bool

    @classmethod
    def parse(cls, text: str) -> Style:
        if not isinstance(text, str) or not text.strip():
            raise ValueError(f"style: expected one of {', '.join(STYLES)}, got {text!r}")
        parts = [p.strip() for p in text.split("+")]
        unknown = [p for p in parts if p not in COMPONENTS]
        if unknown or len(set(parts)) != len(parts):
            raise ValueError(
                f"style: unknown or repeated component(s) {unknown or parts} in {text!r}; "
                f"expected one of {', '.join(STYLES)}"
            )
        return cls(render="render" in parts, markers="markers" in parts, prior="prior" in parts)

    @property
    def name(self) -> str:
        return "+".join(c for c in COMPONENTS if getattr(self, c))

    @property
    def needs_current(self) -> bool:
        """The style needs the current frames and state (the prior warps them)."""
        return self.prior
