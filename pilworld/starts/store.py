"""A folder of subtask starts: what an imagined-only run needs from the robot, and nothing more.

A start (:class:`~pilworld.types.Start`) is the start observation of a subtask and the H_h history
frames before it — the cheap part of a real trial: on hardware the operator lays out the scene and the
rig records a few frames while the arms hold still; no policy runs. ``pilworld paired record-starts``
records them, and every paired run keeps its own in ``RUN/starts/`` so that ``pilworld imagine`` can
rerun its imagined branches, or run other checkpoints from the same scenes.

Layout: an episode store (:mod:`pilworld.data`, lossless video, so frames come back bit for bit) with
one episode per start — the history frames oldest first, then the start frame — plus ``starts.json``
(the robot's limits, which the imagined branch's safety filter applies, and the chunk timing). Each
episode's ``extra.start`` names the subtask (task, index, instruction, layout seed), the index of the
start frame and every frame's timestamp; ``extra.start_id`` is ``task/seed{S}/subtask{K}`` and
``extra.start_checkpoint`` the checkpoint whose real branch began from it ("" when the scene is the same
for every checkpoint, as on the simulated rig); ``extra.task`` and ``extra.task_sha256`` name the task and
the hash of the task file the scene was laid out from.
"""

from __future__ import annotations

import json
from collections.abc import Mapping
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

import numpy as np

from pilworld.data.backup import back_up
from pilworld.data.episode import Episode
from pilworld.data.reader import EpisodeStore
from pilworld.data.spec import DatasetSpec
from pilworld.data.writer import EpisodeWriter
from pilworld.io.atomic import write_json
from pilworld.types import ChunkSpec, Observation, RobotSpec, Start, Subtask

META_FILE = "starts.json"
FORMAT = "pilworld-starts/1"


class StartsError(ValueError):
    """A starts folder (or a store read as one) that cannot give the starts asked for."""


def start_id(subtask: Subtask) -> str:
    """The scene's name, shared by every checkpoint run from it: ``task/seed{S}/subtask{K}``."""
    return f"{subtask.task}/seed{subtask.seed}/subtask{subtask.index}"


@dataclass(frozen=True)
class StoredStart:
    """A start read back from a folder, with the names that tie it to paired runs."""

    start_id: str
    checkpoint: str  # the checkpoint whose real branch began here; "" = the same scene for every checkpoint
    start: Start
    source: str  # where it was read: folder and episode index
    episode_index: int = -1  # the episode it was read from (-1: not read from a folder)
    task_sha256: str = ""  # the hash of the task file the start was recorded with ("" when not recorded)

    @property
    def subtask(self) -> Subtask:
        return self.start.subtask


def robot_spec_json(spec: RobotSpec) -> dict[str, Any]:
    out: dict[str, Any] = json.loads(json.dumps(asdict(spec)))
    return out


def robot_spec_from_json(d: dict[str, Any]) -> RobotSpec:
    return RobotSpec(
        joint_names=tuple(d["joint_names"]),
        lower=tuple(float(v) for v in d["lower"]),
        upper=tuple(float(v) for v in d["upper"]),
        cameras=tuple(d["cameras"]),
        control_rate_hz=float(d["control_rate_hz"]),
        image_size=(int(d["image_size"][0]), int(d["image_size"][1])),
        max_joint_speed=tuple(float(v) for v in d.get("max_joint_speed", ())),
    )


def start_episode(start: Start, *, checkpoint: str = "", task_sha256: str = "") -> Episode:
    """``start`` as one stored episode: history frames, then the start frame (the robot holds still).

    ``task_sha256`` is the hash of the task file the scene was laid out from (``Task.digest``)."""
    frames = [*start.history, start.observation]
    views = list(start.observation.views)
    state = np.stack([np.asarray(o.state, dtype=np.float32) for o in frames])
    sub = start.subtask
    return Episode(
        images={v: np.stack([np.asarray(o.images[v]) for o in frames]) for v in views},
        state=state,
        action=state.copy(),  # holding still: each frame's command is where the arms are
        task=sub.instruction,
        origin="real",
        subtask_index=sub.index,
        checkpoint=checkpoint,
        seed=sub.seed,
        extra={
            "start_id": start_id(sub),
            "start_checkpoint": checkpoint,
            "task": sub.task,
            **({"task_sha256": task_sha256} if task_sha256 else {}),
            "start": {
                "task": sub.task,
                "index": sub.index,
                "instruction": sub.instruction,
                "seed": sub.seed,
                "frame": len(start.history),
                # JSON keeps a float's shortest repr, which reads back to the same double
                "timestamps": [float(o.timestamp) for o in frames],
            },
        },
    )


def _observation(ep: Episode, i: int, timestamp: float) -> Observation:
    return Observation(images={v: ep.images[v][i] for v in ep.images}, state=ep.state[i], timestamp=timestamp)


def start_from_episode(
    ep: Episode, source: str, *, start_frame: int | None, history: int, fps: float, episode_index: int = -1
) -> StoredStart:
    """The start an episode holds: a stored start (``extra.start``), or frame ``start_frame`` of any
    recorded episode with the ``history`` frames before it (frames at the policy's stride)."""
    meta = ep.extra.get("start")
    if isinstance(meta, dict):
        frame = int(meta["frame"])
        stamps = [float(t) for t in meta["timestamps"]]
        sub = Subtask(
            task=str(meta["task"]),
            index=int(meta["index"]),
            instruction=str(meta["instruction"]),
            seed=int(meta["seed"]),
        )
        checkpoint = str(ep.extra.get("start_checkpoint", ""))
        digest = str(ep.extra.get("task_sha256") or "")
        first = 0  # every history frame it was recorded with, as the paired run's branches saw them
    else:
        frame = history if start_frame is None else start_frame
        if not 0 <= frame < ep.length:
            raise StartsError(f"{source}: start frame {frame} is outside the episode's {ep.length} frames")
        stamps = [i / fps for i in range(ep.length)]
        task = str(ep.extra.get("task") or ep.extra.get("sim_task") or ep.task)
        sub = Subtask(task=task, index=ep.subtask_index, instruction=ep.task, seed=ep.seed)
        checkpoint = ""
        digest = str(ep.extra.get("task_sha256") or "")
        first = max(0, frame - history)
    if frame < 1 and history > 0:
        raise StartsError(
            f"{source}: the start has no history frames (the world model keeps {history}); "
            "record starts with their history (pilworld paired record-starts) or pick a later --start-frame"
        )
    start = Start(
        subtask=sub,
        observation=_observation(ep, frame, stamps[frame]),
        history=tuple(_observation(ep, i, stamps[i]) for i in range(first, frame)),
    )
    return StoredStart(start_id(sub), checkpoint, start, source, episode_index, digest)


class StartsWriter:
    """Appends starts to a folder (created on first use); a start already stored is kept, not rewritten."""

    def __init__(
        self,
        root: str | Path,
        spec: DatasetSpec,
        robot: RobotSpec,
        chunk: ChunkSpec,
        *,
        rig: str,
        task_sha256: Mapping[str, str] | None = None,
    ) -> None:
        if spec.video_mode != "lossless":
            raise ValueError(f"starts: stored losslessly so they replay bit for bit, not {spec.video_mode!r}")
        self.root = Path(root)
        self.meta = {
            "format": FORMAT,
            "rig": str(Path(rig).resolve()),  # imagine runs from any folder: not the recording's working directory
            "robot_spec": robot_spec_json(robot),
            "chunk": asdict(chunk),
        }
        path = self.root / META_FILE
        if path.is_file():
            from pilworld.io.run_folder import read_json_object

            have = read_json_object(path)
            diff = sorted(k for k in ("robot_spec", "chunk") if have.get(k) != self.meta[k])
            if diff:
                raise StartsError(f"{self.root}: holds starts recorded with other settings ({', '.join(diff)})")
        self._spec = spec
        self._hashes = dict(task_sha256 or {})  # task name → the hash of its file, recorded with each start
        self._writer: EpisodeWriter | None = None
        self._index: dict[tuple[str, str], int] | None = None
        self._redo: dict[tuple[str, str], int] = {}  # damaged stored starts: rewritten in place by add()

    def _slots(self) -> dict[tuple[str, str], int]:
        """(start id, checkpoint) → episode index of every start in the folder (read once, then kept up to date)."""
        if self._index is None:
            self._index = {}
            if (self.root / "meta" / "info.json").is_file():
                for i, row in enumerate(EpisodeStore(self.root).episodes):
                    extra = json.loads(row.get("extra") or "{}")
                    if "start_id" in extra:
                        self._index[(str(extra["start_id"]), str(extra.get("start_checkpoint", "")))] = i
        return self._index

    def stored(self) -> set[tuple[str, str]]:
        """(start id, checkpoint) of every intact start in the folder (those given to :meth:`redo` are not)."""
        return set(self._slots()) - set(self._redo)

    def redo(self, slots: Mapping[tuple[str, str], int]) -> None:
        """Treat these stored starts ((start id, checkpoint) → episode index; damaged files) as not stored:
        ``add`` then rewrites each into its old episode slot."""
        self._slots()
        self._redo.update(slots)

    def load(self, subtask: Subtask, *, checkpoint: str = "") -> Start:
        """The stored start of ``subtask`` (and ``checkpoint``) as it was recorded, frames bit for bit."""
        key = (start_id(subtask), checkpoint)
        if key not in self.stored():
            raise StartsError(
                f"{self.root}: holds no intact start {key[0]}" + (f" for {checkpoint}" if checkpoint else "")
            )
        index = self._slots()[key]
        ep = EpisodeStore(self.root).load(index)
        return start_from_episode(ep, str(self.root), start_frame=None, history=0, fps=1.0, episode_index=index).start

    def add(self, start: Start, *, checkpoint: str = "", replace: bool = False) -> bool:
        """Store ``start`` unless it is there already; True when it was written.

        ``replace=True`` rewrites a stored start of the same subtask and checkpoint in its slot: on a rig
        whose scenes are set up by hand, a pair run again begins from a new scene, and the folder must hold
        the start its branches ran from."""
        key = (start_id(start.subtask), checkpoint)
        slots = self._slots()
        if key in self.stored() and not replace:
            return False
        if self._writer is None:
            self.root.mkdir(parents=True, exist_ok=True)
            write_json(self.root / META_FILE, self.meta)
            back_up(self.root, [META_FILE])
            self._writer = EpisodeWriter(self.root, self._spec)
        episode = start_episode(start, checkpoint=checkpoint, task_sha256=self._hashes.get(start.subtask.task, ""))
        slot = self._redo.pop(key, None)
        if slot is None:
            slot = slots.get(key)
        if slot is None:
            slots[key] = self._writer.append(episode)
        else:
            self._writer.replace(slot, episode)
        return True

    def close(self) -> None:
        if self._writer is not None:
            self._writer.close()
            self._writer = None

    def __enter__(self) -> StartsWriter:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


def read_meta(root: Path) -> dict[str, Any] | None:
    path = root / META_FILE
    from pilworld.io.run_folder import read_json_object

    return read_json_object(path) if path.is_file() else None
