"""Real branches kept on disk: they do not depend on the world model, so every rung and every rerun shares them."""

from __future__ import annotations

import dataclasses
import json
from pathlib import Path
from typing import Any

import numpy as np

from pilworld.io.atomic import atomic_write
from pilworld.rollout import Rollout
from pilworld.types import Observation, Segment, Start, Subtask


def save_rollout(path: Path, rollout: Rollout, meta: dict[str, Any]) -> None:
    """A real-branch rollout (start, history, segments, chunks) and ``meta`` as one compressed npz."""
    obs = rollout.observations
    views = list(rollout.start.observation.views)
    hist = list(rollout.start.history)
    arrays: dict[str, Any] = {}
    for i, v in enumerate(views):
        arrays[f"img{i}"] = np.stack([np.asarray(o.images[v]) for o in obs])
        if hist:
            arrays[f"hist{i}"] = np.stack([np.asarray(o.images[v]) for o in hist])
    arrays["state"] = np.stack([o.state for o in obs]).astype(np.float32)
    arrays["time"] = np.array([o.timestamp for o in obs], dtype=np.float64)
    arrays["hist_state"] = np.array([o.state for o in hist], dtype=np.float32).reshape(len(hist), -1)
    arrays["hist_time"] = np.array([o.timestamp for o in hist], dtype=np.float64)
    arrays["actions"] = np.stack([s.actions for s in rollout.segments]).astype(np.float32)
    arrays["chunks"] = np.stack(rollout.chunks).astype(np.float32)
    sub = rollout.start.subtask
    info = {
        **meta,
        "views": views,
        "stride": rollout.segments[0].stride,
        "seg_len": [len(s.observations) for s in rollout.segments],
        "subtask": dataclasses.asdict(sub),
        "instruction": rollout.instruction,
        "origin": rollout.origin,
    }
    arrays["meta"] = np.array(json.dumps(info))

    def write(tmp: Path) -> None:
        with tmp.open("wb") as fh:
            np.savez_compressed(fh, **arrays)

    atomic_write(path, write, durable=False)


def load_rollout(path: Path) -> tuple[Rollout, dict[str, Any]]:
    """The rollout and meta :func:`save_rollout` wrote."""
    with np.load(path) as z:
        info = json.loads(str(z["meta"]))
        views = info["views"]
        imgs = [z[f"img{i}"] for i in range(len(views))]
        hists = [z[f"hist{i}"] for i in range(len(views))] if f"hist{0}" in z.files else None
        state, times = z["state"], z["time"]
        hist_state, hist_time = z["hist_state"], z["hist_time"]
        actions, chunks = z["actions"], z["chunks"]

    def obs_at(i: int) -> Observation:
        return Observation(
            images={v: imgs[j][i] for j, v in enumerate(views)}, state=state[i], timestamp=float(times[i])
        )

    history: tuple[Observation, ...] = ()
    if hists is not None:
        history = tuple(
            Observation(
                images={v: hists[j][i] for j, v in enumerate(views)}, state=hist_state[i], timestamp=float(hist_time[i])
            )
            for i in range(len(hist_time))
        )
    start = Start(subtask=Subtask(**info["subtask"]), observation=obs_at(0), history=history)
    segments, at = [], 1
    for r, n in enumerate(info["seg_len"]):
        segments.append(Segment(tuple(obs_at(at + k) for k in range(n)), actions=actions[r], stride=info["stride"]))
        at += n
    rollout = Rollout(
        origin=info["origin"], start=start, instruction=info["instruction"], segments=segments, chunks=list(chunks)
    )
    return rollout, info
