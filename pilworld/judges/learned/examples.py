"""Episodes turned into the learned judge's inputs (:mod:`.inputs`), from a stored dataset or an episode in memory.

An example holds :data:`~.inputs.END_FRAMES` variants of one episode, one per last frame: (E, V, 6, S, S)
uint8 frames and (E, 2·D) float32 states, with one context vector. Reading one from a store decodes only
the first and the last frames of each view (~20 ms a view), not the whole video.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from pilworld.config.rig import RigConfig
from pilworld.data.episode import Episode
from pilworld.data.reader import EpisodeStore, list_column
from pilworld.data.spec import STATE_KEY
from pilworld.judges.learned.inputs import END_FRAMES, InputSpec, JudgeInputError, context_vector, view_stack
from pilworld.judges.learned.release import crop, last_release
from pilworld.types import HEAD_VIEW


@dataclass(frozen=True)
class Example:
    frames: NDArray[np.uint8]  # (E, V, 6, S, S)
    state: NDArray[np.float32]  # (E, 2·D): first state, then the state at that last frame
    context: NDArray[np.float32]  # (CONTEXT_DIM,)
    instruction: str  # as recorded (the context hashes it; the judge also checks it is one it knows)


def release_uv(state: NDArray[np.floating], rig: RigConfig | None) -> tuple[float, float]:
    """The head pixel of the episode's last release; without one, of the tool point that travelled most, at the end."""
    if rig is None:
        raise JudgeInputError("this judge reads where a gripper let go and needs the rig's kinematics and head camera")
    r = last_release(state, rig)
    if r is not None:
        return r.uv
    tcp = rig.kinematics.gripper_points(np.asarray(state, np.float64))  # (T, 2, 3)
    arm = int(np.argmax(np.linalg.norm(np.diff(tcp, axis=0), axis=-1).sum(0)))
    uv, _ = rig.head_camera_model.project(tcp[-1, arm])
    return float(uv[0]), float(uv[1])


def make_example(
    images: Mapping[str, NDArray[np.uint8]],
    state: NDArray[np.float32],
    instruction: str,
    subtask: int,
    spec: InputSpec,
    uv: tuple[float, float] | None = None,
) -> Example:
    """``images``: view → (N, H, W, 3) with the episode's first frame at row 0 and its last frames after it
    (N ≥ 2; the last ``min(END_FRAMES, N - 1)`` rows are the ends), ``state``: (N, D) on the same rows;
    ``uv``: the release pixel in the head view (:func:`release_uv`), for a judge that reads the release crop."""
    n = int(state.shape[0])
    if n < 2:
        raise ValueError(f"an episode needs at least 2 frames to be judged, got {n}")
    ends = list(range(max(1, n - END_FRAMES), n))[::-1]  # latest first
    while len(ends) < END_FRAMES:  # a short episode repeats its last frame
        ends.append(ends[-1])

    def stacks(e: int) -> list[NDArray[np.uint8]]:
        out = [view_stack(images[v][0], images[v][e], spec.side) for v in spec.views]
        if spec.release_crop:
            assert uv is not None, "a release-crop judge needs the release pixel"
            head, size = images[HEAD_VIEW], spec.release_crop
            out.append(view_stack(crop(head[0], uv, size), crop(head[e], uv, size), spec.side))
        return out

    frames = np.stack([np.stack(stacks(e)) for e in ends])
    st = np.stack([np.concatenate([state[0], state[e]]) for e in ends]).astype(np.float32)
    return Example(frames=frames, state=st, context=context_vector(instruction, subtask), instruction=instruction)


def episode_example(episode: Episode, spec: InputSpec, rig: RigConfig | None = None) -> Example:
    """An episode in memory (what a :class:`~pilworld.judges.base.Judge` is given), checked against ``spec``."""
    spec.check({v: f.shape[1:3] for v, f in episode.images.items()}, int(episode.state.shape[1]), "the episode")
    T = episode.length
    rows = [0, *range(max(1, T - END_FRAMES), T)] if T > 1 else [0, 0]
    images = {v: episode.images[v][rows] for v in spec.views}
    uv = release_uv(episode.state, rig) if spec.release_crop else None
    return make_example(images, episode.state[rows], episode.task, episode.subtask_index, spec, uv)


def stored_example(store: EpisodeStore, index: int, spec: InputSpec, rig: RigConfig | None = None) -> Example:
    """Episode ``index`` of ``store``, decoding only the frames the judge reads."""
    table = store.frame_table(index)
    state = list_column(table, STATE_KEY, store.spec.state_dim)
    T = int(state.shape[0])
    labels = store.labels(index, table)
    start = max(1, T - END_FRAMES)
    images = {}
    for v in spec.views:
        first = store.frames(index, v, 0, 1)
        last = store.frames(index, v, start, T - start) if T > 1 else first
        images[v] = np.concatenate([first, last])
    rows = [0, *range(start, T)] if T > 1 else [0, 0]
    uv = release_uv(state, rig) if spec.release_crop else None
    return make_example(images, state[rows], str(labels["task"]), int(labels["subtask_index"]), spec, uv)


def stack_examples(examples: list[Example]) -> tuple[NDArray[np.uint8], NDArray[np.float32], NDArray[np.float32]]:
    """Frames (N, E, V, 6, S, S), states (N, E, 2·D), contexts (N, C)."""
    return (
        np.stack([e.frames for e in examples]),
        np.stack([e.state for e in examples]),
        np.stack([e.context for e in examples]),
    )
