"""Training clips (paper appendix "Clip-Level Training Sample Construction"): the indexing formula.

An episode of ``T`` frames, recorded at the control rate, has frames ``x_0 … x_{T−1}`` and actions
``a[0] … a[T−1]``, where ``a[i]`` is the command sent after observing ``x_i`` (LeRobot's convention).
So the paper's chunk ``A_t = a_{t+1..t+H_π}`` predicted at frame ``t`` starts with ``a[t]``, and its
stride-aligned action ``a_{t+kΔ}`` is ``a[t + kΔ − 1]``, whose result is the frame ``x_{t+kΔ}``.

With stride ``Δ`` (3), ``K`` future frames (15), ``H_h`` history frames (5) and windows ``W``
stride-sampled frames apart (9), clip ``c`` (0-based) of an episode is:

* current frame   ``t_c = c · W · Δ``
* history frames  ``t_c − jΔ`` for ``j = H_h, …, 1`` (oldest first), clamped at 0: frames before the
  episode start repeat ``x_0`` and are flagged in ``history_valid``
* future frames   ``t_c + kΔ`` for ``k = 1, …, K``
* actions         ``a[t_c + kΔ − 1]`` for ``k = 1, …, K`` (the stride-aligned actions)

A clip exists when its last future frame does: ``t_c + KΔ ≤ T − 1``, so an episode has
``N = ⌊(T − 1 − KΔ) / (WΔ)⌋ + 1`` clips when ``T − 1 ≥ KΔ``, else none. With ``include_tail`` one
more clip ends exactly on the last frame (``t = T − 1 − KΔ``) when the regular ones stop short of it,
so the end of every episode — where success or failure shows — is always a training target.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray


@dataclass(frozen=True)
class ClipSpec:
    stride: int = 3  # Δ
    future: int = 15  # K
    history: int = 5  # H_h
    window: int = 9  # W: stride-sampled frames between consecutive clip starts
    include_tail: bool = False  # add a clip ending on the last frame (not in the paper)

    def __post_init__(self) -> None:
        for name in ("stride", "future", "window"):
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, int) or v < 1:
                raise ValueError(f"{name}: expected an integer >= 1, got {v!r}")
        if isinstance(self.history, bool) or not isinstance(self.history, int) or self.history < 0:
            raise ValueError(f"history: expected an integer >= 0, got {self.history!r}")

    @classmethod
    def for_dataset(cls, steps_per_frame: int, control_stride: int = 3, **kwargs: int | bool) -> ClipSpec:
        """The clip spec in *stored* frames for a dataset keeping every ``steps_per_frame``-th control step.

        The paper's Δ = ``control_stride`` control steps; a dataset recorded at the stride (the simulated
        rig's collector) therefore has ``stride = 1``.
        """
        if control_stride % steps_per_frame:
            raise ValueError(
                f"stride: the dataset stores every {steps_per_frame}-th control step, which does not divide "
                f"the stride of {control_stride} control steps"
            )
        return cls(stride=control_stride // steps_per_frame, **kwargs)  # type: ignore[arg-type]

    @property
    def span(self) -> int:
        """K·Δ: frames from the current frame to the last future frame."""
        return self.future * self.stride

    def clip_starts(self, length: int) -> NDArray[np.int64]:
        """Current-frame indices ``t_c`` of every clip of an episode with ``length`` frames."""
        last = length - 1 - self.span  # the latest admissible t_c
        if last < 0:
            return np.zeros(0, dtype=np.int64)
        starts = np.arange(0, last + 1, self.window * self.stride, dtype=np.int64)
        if self.include_tail and starts[-1] != last:
            starts = np.append(starts, np.int64(last))
        return starts

    def history_indices(self, t: int) -> tuple[NDArray[np.int64], NDArray[np.bool_]]:
        """(frame indices oldest first, valid mask) of the H_h history frames of a clip at ``t``."""
        raw = t - np.arange(self.history, 0, -1, dtype=np.int64) * self.stride
        return np.maximum(raw, 0), raw >= 0

    def future_indices(self, t: int) -> NDArray[np.int64]:
        return t + np.arange(1, self.future + 1, dtype=np.int64) * self.stride

    def action_indices(self, t: int) -> NDArray[np.int64]:
        return self.future_indices(t) - 1


@dataclass(frozen=True)
class ClipRef:
    episode_index: int
    t: int  # current frame


def index_clips(lengths: list[int], spec: ClipSpec) -> list[ClipRef]:
    """Every clip of every episode, episode by episode."""
    return [ClipRef(e, int(t)) for e, n in enumerate(lengths) for t in spec.clip_starts(n)]


def mix_weights(success: NDArray[np.int8], success_fraction: float | None) -> NDArray[np.float64]:
    """Per-clip sampling weights for a success/failure mix (sum 1).

    ``success`` holds 1 (episode succeeded), 0 (failed) or −1 (unknown) per clip. ``None`` samples
    clips uniformly. Otherwise the labelled clips' share of the mass is split ``success_fraction``
    to successes and the rest to failures; unknown clips keep their uniform share.
    """
    n = len(success)
    if n == 0:
        raise ValueError("mix_weights: no clips")
    w = np.full(n, 1.0 / n)
    if success_fraction is None:
        return w
    if not 0.0 <= success_fraction <= 1.0:
        raise ValueError(f"success_fraction: expected a value in [0, 1], got {success_fraction!r}")
    pos, neg = success == 1, success == 0
    labelled = (pos | neg).sum() / n
    for mask, share in ((pos, success_fraction), (neg, 1.0 - success_fraction)):
        if share > 0 and not mask.any():
            kind = "successful" if mask is pos else "failed"
            raise ValueError(f"success_fraction={success_fraction}: the dataset has no clips from {kind} episodes")
        if mask.any():
            w[mask] = labelled * share / mask.sum()
    out: NDArray[np.float64] = w / w.sum()
    return out
