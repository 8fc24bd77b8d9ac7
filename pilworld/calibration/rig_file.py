"""A copy of a rig config that points at a calibrated wrist camera (``calibrate handeye --write-rig``).

The copy's ``wrist_cameras.<name>.file`` is the new camera model; every other relative camera file is
re-based so the copy loads from its own folder, and the copy is loaded once to prove it (docs/calibration.md,
"Wrist cameras (eye-in-hand)").
"""

from __future__ import annotations

import os
from pathlib import Path

import yaml

from pilworld.config.rig import RigConfig

__all__ = ["write_rig_with_camera"]


def write_rig_with_camera(rig_path: Path, out: Path, camera: str, model: Path) -> None:
    """A copy of the rig YAML with ``wrist_cameras.<camera>.file`` = ``model``; other camera files re-based."""
    doc = yaml.safe_load(rig_path.read_text(encoding="utf-8"))
    src, dst = rig_path.resolve().parent, out.resolve().parent

    def rebase(value: str) -> str:
        path = Path(value).expanduser()
        return value if path.is_absolute() else os.path.relpath(src / path, dst)

    head = doc.get("head_camera") or {}
    if head.get("file"):
        head["file"] = rebase(str(head["file"]))
    for cam_name, cam in (doc.get("wrist_cameras") or {}).items():
        if cam_name != camera and cam.get("file"):
            cam["file"] = rebase(str(cam["file"]))
    doc["wrist_cameras"][camera]["file"] = os.path.relpath(model.resolve(), dst)
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(
        f"# Written by `pilworld calibrate handeye --camera {camera} --write-rig`: {rig_path} with the calibrated "
        f"{camera}.\n" + yaml.safe_dump(doc, sort_keys=False),
        encoding="utf-8",
    )
    RigConfig.load(out)  # the copy must load (the model file exists, the fields validate)
