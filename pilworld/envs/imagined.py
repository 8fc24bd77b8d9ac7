"""The imagined branch: the world model in place of the robot (paper §3.1–3.2, DESIGN.md "Data flow").

One round: the chunk's K stride-aligned actions → the head-view control video Γ (forward kinematics,
projected with the rig's head camera, drawn from the policy-side state) → the world model predicts K
frames of every view from the current frame, the H_h history frames and the instruction → K
observations. The history memory then takes the generated frames (it starts from the real frames of
the shared start), and the policy-side state becomes the last stride-aligned action, since actions are
absolute joint commands the imagined robot is assumed to reach — unless the model predicts the state
itself (``predict_with_state``, world model v2): then the policy sees the state the model says the
robot will report (a gripper resting on a held cube measures its width, not the closed command).
Every request carries the current state (``PredictRequest.state``), which geometry-based models need.

Frame times advance by Δ control periods per frame, as the real branch's do.

With ``safety`` the chunk first goes through the same safety filter as on the robot (joint limits and
speed, from the start state on), so the world model is conditioned on the commands the robot would
really execute, not on a jump the robot would have slowed down.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
from numpy.typing import NDArray

from hw_drivers.safety import SafetyFilter
from pilworld.control_video.gamma import ControlVideo
from pilworld.envs.base import EnvError, as_chunk
from pilworld.types import ActionChunk, ChunkSpec, Observation, Segment, Start
from pilworld.world_model.base import PredictRequest, StatefulRollout, StatePrediction, WorldModel


class HistoryMemory:
    """The last H_h frames of every view before the current one, oldest first, with validity flags.

    A start with fewer than H_h history frames is padded at the front with copies of its oldest frame
    (or of the current frame) flagged invalid — the same rule training clips use at an episode start.
    The joint state of each frame is kept beside it (models that render the robot need to know where
    it was in each remembered frame).
    """

    def __init__(self, views: Sequence[str], size: int) -> None:
        self.views = tuple(views)
        self.size = size
        self._frames: dict[str, list[NDArray[np.uint8]]] = {v: [] for v in self.views}
        self._states: list[NDArray[np.float32]] = []
        self._valid: list[bool] = []

    def reset(self, history: Sequence[Observation], current: Observation) -> None:
        recent = list(history)[-self.size :] if self.size else []
        pad = self.size - len(recent)
        first = recent[0] if recent else current
        self._frames = {
            v: [np.asarray(first.images[v])] * pad + [np.asarray(o.images[v]) for o in recent] for v in self.views
        }
        self._states = [np.asarray(first.state, np.float32)] * pad + [np.asarray(o.state, np.float32) for o in recent]
        self._valid = [False] * pad + [True] * len(recent)

    def push(self, frames: dict[str, NDArray[np.uint8]], state: NDArray[np.floating] | None = None) -> None:
        """Append one frame per view (the previous current frame or a generated one); keep the last H_h."""
        if not self.size:
            return
        for v in self.views:
            self._frames[v] = [*self._frames[v], frames[v]][-self.size :]
        last = self._states[-1] if self._states else np.zeros(0, np.float32)
        st = last if state is None else np.asarray(state, np.float32)
        self._states = [*self._states, st][-self.size :]
        self._valid = [*self._valid, True][-self.size :]

    def arrays(self) -> tuple[dict[str, NDArray[np.uint8]], NDArray[np.bool_]]:
        return {v: np.stack(f) for v, f in self._frames.items()} if self.size else {}, np.array(self._valid, dtype=bool)

    def states(self) -> NDArray[np.float32] | None:
        """(H_h, 14) joint states of the remembered frames (None without memory)."""
        return np.stack(self._states) if self.size and self._states else None


class ImaginedEnv:
    """The imagined branch over any :class:`~pilworld.world_model.base.WorldModel`."""

    def __init__(
        self,
        model: WorldModel,
        control_video: ControlVideo,
        spec: ChunkSpec | None = None,
        *,
        control_rate_hz: float = 30.0,
        seed: int = 0,
        steps: int | None = None,
        safety: SafetyFilter | None = None,
    ) -> None:
        self.model = model
        self.safety = safety
        self.gamma = control_video
        self._spec = spec or control_video.spec
        info = model.info
        if info.future != self._spec.frames:
            raise EnvError(
                f"the world model predicts {info.future} frames per call, the chunk spec needs K = {self._spec.frames}"
            )
        if control_video.spec.frames != self._spec.frames or control_video.spec.stride != self._spec.stride:
            raise EnvError("the control video's chunk spec (K, Δ) differs from the environment's")
        if (control_video.width, control_video.height) != (info.width, info.height):
            raise EnvError(
                f"the control video is {control_video.width}x{control_video.height}, "
                f"the world model expects {info.width}x{info.height}"
            )
        self.control_rate_hz = control_rate_hz
        self.seed = seed
        self.steps = steps
        self.memory = HistoryMemory(info.views, info.history)
        self._obs: Observation | None = None
        self._instruction = ""
        self._round = 0

    @property
    def origin(self) -> str:
        return "imagined"

    @property
    def spec(self) -> ChunkSpec:
        return self._spec

    def reset(self, start: Start) -> Observation:
        info = self.model.info
        obs = start.observation
        if set(obs.views) != set(info.views):
            raise EnvError(f"the start has views {sorted(obs.views)}, the world model predicts {sorted(info.views)}")
        for v in info.views:
            if obs.image_size(v) != (info.width, info.height):
                w, h = obs.image_size(v)
                raise EnvError(
                    f"start image {v!r} is {w}x{h}, the world model expects {info.width}x{info.height} "
                    "(set the rig's image_size to the model's)"
                )
        self.memory.reset(start.history, obs)
        if self.safety is not None:
            self.safety.reset(obs.state)
        self._obs = obs
        self._instruction = start.subtask.instruction  # conditions the world model
        if isinstance(self.model, StatefulRollout):  # it carries state across the chunks (v2: tracked objects)
            self.model.begin_rollout(dict(obs.images), obs.state, self._instruction)
        self._round = 0
        return obs

    def step(self, chunk: ActionChunk | NDArray[np.floating]) -> Segment:
        if self._obs is None:
            raise EnvError("step() before reset(): call reset(start) first")
        spec = self._spec
        c = as_chunk(chunk, spec, int(self._obs.state.shape[0]))
        executed = c.executed(spec)
        if self.safety is not None:
            executed = np.stack([self.safety(a) for a in executed])
        stride_actions = executed[spec.stride_indices()]
        control = self.gamma.render_stride_aligned(stride_actions[None].astype(np.float64), self._obs.state[None])[0]
        history, valid = self.memory.arrays()
        request = PredictRequest.build(
            self.model.info,
            current=dict(self._obs.images),
            history=history if self.memory.size else None,
            history_valid=valid if self.memory.size else None,
            control=control,
            actions=stride_actions,
            instruction=self._instruction,
            state=self._obs.state,
            history_state=self.memory.states(),
        )
        # A different seed per round, fixed per (env seed, round): reruns reproduce the same rollout.
        seed = self.seed * 1000 + self._round
        if isinstance(self.model, StatePrediction):
            # A model that predicts the state the robot will report (v2: a gripper resting on what it holds).
            frames, states = self.model.predict_with_state(request, steps=self.steps, seed=seed)
            states = np.asarray(states, dtype=np.float32)
            if states.shape != stride_actions.shape or not np.all(np.isfinite(states)):
                raise EnvError(
                    f"the world model predicted states of shape {states.shape}, expected {stride_actions.shape}"
                )
        else:
            frames = self.model.predict(request, steps=self.steps, seed=seed)
            states = stride_actions.astype(np.float32)
        dt = spec.stride / self.control_rate_hz
        t0 = self._obs.timestamp
        observations = tuple(
            Observation(
                images={v: frames[v][k] for v in self.model.info.views},
                state=states[k],
                timestamp=t0 + (k + 1) * dt,
            )
            for k in range(spec.frames)
        )
        # Memory: the old current frame, then every generated frame but the last (the new current).
        self.memory.push(dict(self._obs.images), self._obs.state)
        for o in observations[:-1]:
            self.memory.push(dict(o.images), o.state)
        segment = Segment(observations=observations, actions=executed, stride=spec.stride)
        self._obs = segment.last
        self._round += 1
        return segment
