"""What a dataset holds: fps, camera views and sizes, state/action names, video mode → LeRobot features.

A :class:`DatasetSpec` is fixed when a dataset is created and is written into ``meta/info.json`` as
LeRobot v3.0 ``features`` (every per-frame column with dtype, shape and names) and into
``meta/pilworld.json`` (our own settings, which LeRobot ignores).
"""

from __future__ import annotations

import re
from dataclasses import dataclass, field
from typing import Any

from pilworld.data.video_codec import VIDEO_MODES, codec_settings
from pilworld.types import DEFAULT_VIEWS, dual_arm_joint_names

CODEBASE_VERSION = "v3.0"
PILWORLD_FORMAT = "pilworld.episodes/v1"
IMAGE_PREFIX = "observation.images."
STATE_KEY = "observation.state"
ACTION_KEY = "action"
ORIGINS = ("real", "imagined")

# LeRobot's per-frame bookkeeping columns (every v3.0 dataset has them).
INDEX_FEATURES: dict[str, dict[str, Any]] = {
    "timestamp": {"dtype": "float32", "shape": [1], "names": None},
    "frame_index": {"dtype": "int64", "shape": [1], "names": None},
    "episode_index": {"dtype": "int64", "shape": [1], "names": None},
    "index": {"dtype": "int64", "shape": [1], "names": None},
    "task_index": {"dtype": "int64", "shape": [1], "names": None},
}
# Our per-frame columns: which branch, which subtask and round, which policy checkpoint and seed.
PILWORLD_FEATURES: dict[str, dict[str, Any]] = {
    "origin": {"dtype": "string", "shape": [1], "names": None},
    "subtask_index": {"dtype": "int64", "shape": [1], "names": None},
    "round_index": {"dtype": "int64", "shape": [1], "names": None},
    "checkpoint": {"dtype": "string", "shape": [1], "names": None},
    "seed": {"dtype": "int64", "shape": [1], "names": None},
}

_VIEW_RE = re.compile(r"^[A-Za-z0-9_\-]+$")


@dataclass(frozen=True)
class DatasetSpec:
    """The fixed shape of a dataset; every episode written to it must match."""

    fps: int = 30  # frames per second of the stored frames (LeRobot: integer)
    views: dict[str, tuple[int, int]] = field(
        default_factory=lambda: {v: (128, 128) for v in DEFAULT_VIEWS}
    )  # view → (height, width)
    state_names: tuple[str, ...] = dual_arm_joint_names()
    action_names: tuple[str, ...] = dual_arm_joint_names()
    video_mode: str = "h264"  # h264 | lossless | av1 (see pilworld.data.video_codec)
    robot_type: str = "dual_ur5e"
    # Control steps between stored frames: 1 = every step (frames at the control rate); the simulated
    # rig's collector stores every Δ-th step (3), so its clips use stride 1 (see ClipSpec.for_dataset).
    steps_per_frame: int = 1

    def __post_init__(self) -> None:
        if isinstance(self.fps, bool) or not isinstance(self.fps, int) or not 0 < self.fps <= 1000:
            raise ValueError(f"fps: expected an integer in 1..1000, got {self.fps!r}")
        if not self.views:
            raise ValueError("views: a dataset needs at least one camera view")
        for view, size in self.views.items():
            if not _VIEW_RE.match(view):
                raise ValueError(f"views: camera key {view!r} may only use letters, digits, '_' and '-'")
            if len(size) != 2 or not all(isinstance(s, int) and s > 0 for s in size):
                raise ValueError(f"views[{view!r}]: expected (height, width) positive integers, got {size!r}")
        for name in ("state_names", "action_names"):
            names = getattr(self, name)
            if not names or len(set(names)) != len(names):
                raise ValueError(f"{name}: expected unique non-empty names, got {names!r}")
        spf = self.steps_per_frame
        if isinstance(spf, bool) or not isinstance(spf, int) or spf < 1:
            raise ValueError(f"steps_per_frame: expected an integer >= 1, got {spf!r}")
        if self.video_mode not in VIDEO_MODES:
            raise ValueError(f"video_mode: expected one of {list(VIDEO_MODES)}, got {self.video_mode!r}")
        settings = codec_settings(self.video_mode)
        if settings.pix_fmt == "yuv420p":
            odd = {v: s for v, s in self.views.items() if s[0] % 2 or s[1] % 2}
            if odd:
                raise ValueError(f"views: {self.video_mode} needs even image sizes, got {odd}; use 'lossless'")

    @property
    def state_dim(self) -> int:
        return len(self.state_names)

    @property
    def action_dim(self) -> int:
        return len(self.action_names)

    @staticmethod
    def video_key(view: str) -> str:
        return IMAGE_PREFIX + view

    def features(self) -> dict[str, dict[str, Any]]:
        """LeRobot v3.0 ``features`` for ``meta/info.json``."""
        settings = codec_settings(self.video_mode)
        feats: dict[str, dict[str, Any]] = {
            STATE_KEY: {"dtype": "float32", "shape": [self.state_dim], "names": list(self.state_names)},
            ACTION_KEY: {"dtype": "float32", "shape": [self.action_dim], "names": list(self.action_names)},
        }
        for view, (h, w) in self.views.items():
            feats[self.video_key(view)] = {
                "dtype": "video",
                "shape": [h, w, 3],
                "names": ["height", "width", "channels"],
                "info": {
                    "video.height": h,
                    "video.width": w,
                    "video.codec": settings.info_codec,
                    "video.pix_fmt": settings.pix_fmt,
                    "video.is_depth_map": False,
                    "video.fps": self.fps,
                    "video.channels": 3,
                    "has_audio": False,
                },
            }
        feats.update({k: dict(v) for k, v in INDEX_FEATURES.items()})
        feats.update({k: dict(v) for k, v in PILWORLD_FEATURES.items()})
        return feats

    def to_json(self) -> dict[str, Any]:
        """Our own settings for ``meta/pilworld.json``."""
        return {
            "format": PILWORLD_FORMAT,
            "fps": self.fps,
            "views": {v: list(s) for v, s in self.views.items()},
            "state_names": list(self.state_names),
            "action_names": list(self.action_names),
            "video_mode": self.video_mode,
            "robot_type": self.robot_type,
            "steps_per_frame": self.steps_per_frame,
        }

    @classmethod
    def from_json(cls, data: dict[str, Any], *, source: str) -> DatasetSpec:
        if not isinstance(data, dict):
            raise ValueError(f"{source}: expected a JSON object, found {type(data).__name__}")
        if data.get("format") != PILWORLD_FORMAT:
            raise ValueError(f"{source}: field 'format': expected {PILWORLD_FORMAT!r}, got {data.get('format')!r}")
        try:
            return cls(
                fps=data["fps"],
                views={v: (int(s[0]), int(s[1])) for v, s in data["views"].items()},
                state_names=tuple(data["state_names"]),
                action_names=tuple(data["action_names"]),
                video_mode=data["video_mode"],
                robot_type=data.get("robot_type", ""),
                steps_per_frame=int(data.get("steps_per_frame", 1)),
            )
        except KeyError as err:
            raise ValueError(f"{source}: missing field {err.args[0]!r}") from None
        except (TypeError, AttributeError, IndexError) as err:
            raise ValueError(f"{source}: a field has the wrong shape ({err})") from None


def spec_difference(old: DatasetSpec, new: DatasetSpec) -> str:
    """What differs between two specs, as ``field: X there, Y now; …`` (never the whole repr)."""
    a, b = old.to_json(), new.to_json()
    diff = [
        f"{k}: {_short(a.get(k))} there, {_short(b.get(k))} now"
        for k in sorted(set(a) | set(b))
        if a.get(k) != b.get(k)
    ]
    return "; ".join(diff) or "the same fields, in another form"


def _short(value: Any) -> str:
    text = repr(value)
    return text if len(text) <= 60 else text[:57] + "..."
