"""What each checkpoint's policy server announced, kept in the run folder, and its ``reset_pose``.

An openpi server sends a metadata map at the websocket handshake (often empty; openpi's ALOHA configs
send ``{"reset_pose": [6 joint angles]}``, which its ALOHA runtime moves both arms to before each
episode). A paired run stores every checkpoint's metadata in ``policy_metadata.json`` (one entry per
checkpoint, as received at the run's latest start, arrays as lists) and honours ``reset_pose``:

* on a hardware rig (real, or the fake rig) the arms move to it, at the rig's capped ``start_speed``,
  instead of the configured ``hardware.start_pose`` before each of that checkpoint's subtasks;
* on the simulated rig it is not applied — a subtask's start is laid out with the arms at home so
  that both branches and every checkpoint share it bit for bit — and the run says so in one line.

A ``reset_pose`` has 14 values (the state layout: left joints, left gripper, right joints, right
gripper), 12 (left then right joints; grippers as in the start pose) or 6 (openpi's ALOHA
convention: the same joint angles for both arms; grippers as in the start pose). Anything else is a
:class:`~pilworld.policies.base.PolicyError` of kind "invalid metadata", raised before any motion.
"""

from __future__ import annotations

import json
import sys
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from pilworld.data.backup import back_up
from pilworld.io.atomic import write_json
from pilworld.policies.base import PolicyError
from pilworld.types import ARM_LAYOUT, LEFT_ARM, RIGHT_ARM, STATE_DIM

METADATA_FILE = "policy_metadata.json"
RESET_POSE_KEY = "reset_pose"


def jsonable(value: Any) -> Any:
    """Server metadata as JSON: arrays and numpy scalars as lists and numbers, bytes as text (or hex)."""
    if isinstance(value, Mapping):
        return {(k.decode(errors="replace") if isinstance(k, bytes) else str(k)): jsonable(v) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [jsonable(v) for v in value]
    if isinstance(value, np.ndarray):
        return jsonable(value.tolist())
    if isinstance(value, np.generic):
        return jsonable(value.item())
    if isinstance(value, bytes):
        try:
            return value.decode()
        except UnicodeDecodeError:
            return {"hex": value.hex()}
    if isinstance(value, float) and not np.isfinite(value):
        return str(value)  # JSON has no NaN/inf
    if value is None or isinstance(value, bool | int | float | str):
        return value
    return repr(value)


def server_metadata(policy: object) -> dict[str, Any] | None:
    """The handshake metadata of a remote policy (an ``OpenPiClient``); None for a local one."""
    metadata = getattr(policy, "metadata", None)
    return dict(metadata) if isinstance(metadata, Mapping) else None


def store_metadata(root: Path, policies: Mapping[str, object]) -> dict[str, Any]:
    """Write each remote checkpoint's metadata into ``root/policy_metadata.json`` (others kept); returns it all."""
    path = root / METADATA_FILE
    stored: dict[str, Any] = json.loads(path.read_text()) if path.is_file() else {}
    for checkpoint, policy in policies.items():
        metadata = server_metadata(policy)
        if metadata is not None:
            stored[checkpoint] = jsonable(metadata)
    if stored:
        write_json(path, stored)
        back_up(root, [METADATA_FILE])
    return stored


def reset_pose(
    checkpoint: str, metadata: Mapping[str, Any], start_pose: NDArray[np.float64]
) -> NDArray[np.float64] | None:
    """The 14-d pose ``metadata["reset_pose"]`` asks for (see the module text), or None if it asks for none."""
    if RESET_POSE_KEY not in metadata or metadata[RESET_POSE_KEY] is None:
        return None

    def bad(why: str) -> PolicyError:
        return PolicyError(
            checkpoint,
            f"server metadata reset_pose {why} (expected 14, 12 or 6 finite numbers)",
            kind="invalid metadata",
        )

    try:
        values = np.asarray(metadata[RESET_POSE_KEY], dtype=np.float64)
    except (TypeError, ValueError):
        raise bad(f"is not a list of numbers: {metadata[RESET_POSE_KEY]!r}") from None
    if values.ndim != 1 or not np.all(np.isfinite(values)):
        raise bad(f"has shape {values.shape} or non-finite values")
    pose = np.array(start_pose, dtype=np.float64)
    if values.shape[0] == STATE_DIM:
        pose = values.copy()
    elif values.shape[0] == 12:
        pose[LEFT_ARM], pose[RIGHT_ARM] = values[:6], values[6:]
    elif values.shape[0] == 6:
        pose[LEFT_ARM], pose[RIGHT_ARM] = values, values
    else:
        raise bad(f"has {values.shape[0]} values")
    grips = [pose[grip] for _, grip in ARM_LAYOUT.values()]
    if not all(0.0 <= g <= 1.0 for g in grips):
        raise bad(f"asks for gripper openings {grips}, outside 0..1")
    return pose


def honour_reset_poses(station: object, policies: Mapping[str, object]) -> dict[str, NDArray[np.float64]]:
    """Give a hardware station each checkpoint's ``reset_pose``; on the simulated rig say in one line
    (stderr) that it is not applied. Returns the poses that will be used, by checkpoint."""
    from pilworld.paired.stations import HardwareStation

    poses: dict[str, NDArray[np.float64]] = {}
    for checkpoint, policy in policies.items():
        metadata = server_metadata(policy)
        if not metadata or metadata.get(RESET_POSE_KEY) is None:
            continue
        if not isinstance(station, HardwareStation):
            print(
                f"pilworld: warning: checkpoint {checkpoint}: the server's reset_pose is not applied on the "
                "simulated rig (its starts are laid out with the arms at home, shared by both branches and every "
                f"checkpoint); it is stored in {METADATA_FILE}",
                file=sys.stderr,
            )
            continue
        pose = reset_pose(checkpoint, metadata, station.start_pose())
        if pose is not None:
            poses[checkpoint] = pose
    if isinstance(station, HardwareStation):
        station.reset_poses.update(poses)
    return poses
