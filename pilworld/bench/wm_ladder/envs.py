"""Real branches seen as the imagined branch sees them: its state contract (rung 0), autoencoded frames (rung 1)."""

from __future__ import annotations

from typing import Any

import numpy as np
from numpy.typing import NDArray

from pilworld.bench.wm_ladder.model import FrameAutoencoder
from pilworld.bench.wm_ladder.settings import GRIPS, STATE_MODES
from pilworld.types import ActionChunk, ChunkSpec, Observation, Segment, Start


class _Wrapped:
    """Delegates the :class:`~pilworld.envs.base.Env` contract to ``env``."""

    def __init__(self, env: Any) -> None:
        self.env = env

    @property
    def origin(self) -> str:
        return str(self.env.origin)

    @property
    def spec(self) -> ChunkSpec:
        spec: ChunkSpec = self.env.spec
        return spec


class StateContractEnv(_Wrapped):
    """A real branch whose observations report the imagined branch's state contract.

    ``commanded``: every observation's state is the executed stride-aligned command
    (``segment.actions[spec.stride_indices()]``), as :class:`~pilworld.envs.ImaginedEnv` reports it;
    ``arms_commanded``: the arm joints commanded, the grippers measured; ``real``: unchanged. The start
    observation is the real start in every mode (the imagined branch starts from it too). Images are the
    simulator's own. ``gaps`` collects |reported − measured| per observation (arms, grippers).
    """

    def __init__(self, env: Any, mode: str) -> None:
        if mode not in STATE_MODES:
            raise ValueError(f"mode: expected one of {list(STATE_MODES)}, got {mode!r}")
        super().__init__(env)
        self.mode = mode
        self.gaps: list[tuple[float, float]] = []

    def reset(self, start: Start) -> Observation:
        self.gaps = []
        obs: Observation = self.env.reset(start)
        return obs

    def step(self, chunk: ActionChunk | NDArray[np.floating]) -> Segment:
        seg: Segment = self.env.step(chunk)
        if self.mode == "real":
            return seg
        commanded = np.asarray(seg.actions, dtype=np.float32)[self.spec.stride_indices()]
        grips = list(GRIPS)
        observations = []
        for k, o in enumerate(seg.observations):
            measured = np.asarray(o.state, dtype=np.float32)
            state = commanded[k].copy()
            if self.mode == "arms_commanded":
                state[grips] = measured[grips]
            diff = np.abs(state - measured)
            arms = np.ones(diff.shape[0], dtype=bool)
            arms[grips] = False
            self.gaps.append((float(diff[arms].mean()), float(diff[grips].mean())))
            observations.append(Observation(images=o.images, state=state, timestamp=o.timestamp))
        return Segment(observations=tuple(observations), actions=seg.actions, stride=seg.stride)


class AutoencodedEnv(_Wrapped):
    """A branch whose every observation (the start included) reaches the policy through ``autoencode``.

    Only the images change; states, timestamps and what the robot executes are untouched. ``start_observation``
    is the autoencoded start the policy saw; ``mse`` collects per-view squared errors (levels²) of the
    autoencoded frames against the originals.
    """

    def __init__(self, env: Any, autoencode: FrameAutoencoder) -> None:
        super().__init__(env)
        self.autoencode = autoencode
        self.start_observation: Observation | None = None
        self.mse: dict[str, list[float]] = {}

    def _convert(self, o: Observation) -> Observation:
        images = self.autoencode.images(o.images)
        for v, img in images.items():
            err = np.asarray(img, dtype=np.float64) - np.asarray(o.images[v], dtype=np.float64)
            self.mse.setdefault(v, []).append(float(np.mean(err**2)))
        return Observation(images=images, state=o.state, timestamp=o.timestamp)

    def reset(self, start: Start) -> Observation:
        self.mse = {}
        self.start_observation = self._convert(self.env.reset(start))
        return self.start_observation

    def step(self, chunk: ActionChunk | NDArray[np.floating]) -> Segment:
        seg: Segment = self.env.step(chunk)
        views = list(seg.observations[0].images)
        flat = np.stack([np.asarray(o.images[v]) for o in seg.observations for v in views])
        done = self.autoencode(flat).reshape(len(seg.observations), len(views), *flat.shape[1:])
        observations = []
        for k, o in enumerate(seg.observations):
            for i, v in enumerate(views):
                err = done[k, i].astype(np.float64) - np.asarray(o.images[v], dtype=np.float64)
                self.mse.setdefault(v, []).append(float(np.mean(err**2)))
            images = {v: done[k, i] for i, v in enumerate(views)}
            observations.append(Observation(images=images, state=o.state, timestamp=o.timestamp))
        return Segment(observations=tuple(observations), actions=seg.actions, stride=seg.stride)
