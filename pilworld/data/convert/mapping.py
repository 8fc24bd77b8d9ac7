"""How a source dataset maps onto ours: which cameras become which views, which columns are state/action.

A mapping is optional (``pilworld data convert --mapping MAP.yaml``); without one every camera is kept
under its source name (stripped of ``observation.images.``) and the format's default state/action keys
are used. Example for a RealSource World task (LeRobot v2.1, 17-d actions, 720×1280 cameras)::

    cameras:                      # source camera → our view name; unlisted cameras are dropped
      observation.images.head: cam_high
      left_hand: cam_left_wrist   # the observation.images. prefix may be left out
      right_hand: cam_right_wrist
    resize: [224, 224]            # [height, width], OpenCV INTER_AREA
    state_key: observation.state  # the defaults, shown for completeness
    action_key: action

and for ALOHA HDF5 (which has no instruction)::

    cameras: {cam_high: cam_high, cam_left_wrist: cam_left_wrist, cam_right_wrist: cam_right_wrist}
    task: transfer the cube to the other arm
"""

from __future__ import annotations

import re
from pathlib import Path
from typing import Literal

from pydantic import Field, field_validator

from pilworld.config.loader import StrictModel, load_yaml_model, validate_model
from pilworld.data.spec import IMAGE_PREFIX

_VIEW_RE = re.compile(r"^[A-Za-z0-9_\-]+$")  # what DatasetSpec accepts as a view name
_INVALID_VIEW_CHARS = re.compile(r"[^A-Za-z0-9_\-]")


def default_view_name(source_key: str) -> str:
    """Our view name for a source camera key when no mapping names it.

    ``observation.images.cam_high`` → ``cam_high``; other LeRobot keys lose ``observation.``
    (``observation.image`` → ``image``, as in PushT); characters a view name may not hold become ``_``.
    """
    name = source_key.removeprefix("/")
    name = name.removeprefix(IMAGE_PREFIX) if name.startswith(IMAGE_PREFIX) else name.removeprefix("observation.")
    return _INVALID_VIEW_CHARS.sub("_", name) or "view"


class ConvertMapping(StrictModel):
    """Validated mapping of one source onto our :class:`~pilworld.data.spec.DatasetSpec`.

    Every field is optional; ``None`` means "the format's default" (see the module docstring).
    """

    cameras: dict[str, str] | None = None  # source camera key → our view name (order kept)
    state_key: str | None = None  # LeRobot: observation.state; ALOHA: /observations/qpos
    action_key: str | None = None  # LeRobot: action; ALOHA: /action
    resize: tuple[int, int] | None = None  # [height, width] of every output view
    task: str | None = None  # instruction for episodes that carry none (always used for ALOHA)
    origin: Literal["real", "imagined"] | None = None  # None: the source's label, else "real"
    fps: int | None = Field(default=None, gt=0, le=1000)  # relabels the rate; frames are never resampled
    robot_type: str | None = None  # written to meta/info.json; default: the source's
    # Channel order of the arrays stored in HDF5 files. ALOHA's recorders store RGB (and JPEG-encode
    # those RGB arrays as they are), so "rgb" is right for them; "bgr" is for recorders that stored
    # OpenCV-native BGR arrays.
    color_order: Literal["rgb", "bgr"] = "rgb"

    @field_validator("cameras")
    @classmethod
    def _check_cameras(cls, value: dict[str, str] | None) -> dict[str, str] | None:
        if value is None:
            return None
        if not value:
            raise ValueError("needs at least one camera (leave the field out to keep them all)")
        views: dict[str, str] = {}
        for key, view in value.items():
            name = view.removeprefix(IMAGE_PREFIX)  # accept {cam_high: observation.images.top}
            if not _VIEW_RE.match(name):
                raise ValueError(f"view name {view!r} (for {key!r}) may only use letters, digits, '_' and '-'")
            if name in views.values():
                raise ValueError(f"view name {name!r} is used for more than one camera")
            views[key] = name
        return views

    @field_validator("resize")
    @classmethod
    def _check_resize(cls, value: tuple[int, int] | None) -> tuple[int, int] | None:
        if value is not None and not all(0 < s <= 8192 for s in value):
            raise ValueError(f"expected [height, width] in 1..8192, got {list(value)}")
        return value

    @field_validator("task")
    @classmethod
    def _check_task(cls, value: str | None) -> str | None:
        if value is not None and not value.strip():
            raise ValueError("an instruction must not be empty")
        return value

    @field_validator("state_key", "action_key")
    @classmethod
    def _check_key(cls, value: str | None) -> str | None:
        if value is not None and not value.strip():
            raise ValueError("a column key must not be empty")
        return value

    def with_overrides(self, **changes: object) -> ConvertMapping:
        """A copy with some fields replaced, validated again (``model_copy`` would skip validation)."""
        data = self.model_dump()
        data.update({k: v for k, v in changes.items() if v is not None})
        return validate_model(ConvertMapping, data, source="command line")

    def select_cameras(self, available: list[str], *, source: str) -> dict[str, str]:
        """Source camera key → our view name, for the cameras this mapping keeps.

        A mapping key matches a source key exactly or with the ``observation.images.`` prefix (or
        the leading ``/`` of an HDF5 path) added. Raises ``ValueError`` naming ``source`` and listing
        the available cameras when a mapped camera is missing.
        """
        if self.cameras is None:
            selected = {key: default_view_name(key) for key in available}
            clash = sorted({v for v in selected.values() if list(selected.values()).count(v) > 1})
            if clash:
                raise ValueError(f"{source}: cameras {sorted(available)} give the same view names {clash}; map them")
            return selected
        out: dict[str, str] = {}
        for key, view in self.cameras.items():
            candidates = (key, IMAGE_PREFIX + key, key.removeprefix("/"))
            match = next((c for c in candidates if c in available), None)
            if match is None:
                raise ValueError(f"{source}: camera {key!r} not in the source (available: {sorted(available)})")
            out[match] = view
        return out


def load_mapping(path: str | Path) -> ConvertMapping:
    """Read a mapping YAML; errors (``ConfigError``, a ``ValueError``) name the file and the field."""
    return load_yaml_model(ConvertMapping, path)
