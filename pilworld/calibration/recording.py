"""Hand-eye recordings: the board images and joint states a calibration used, saved so it can be redone offline.

Folder layout (written by ``pilworld calibrate handeye --save DIR``, read by ``--from DIR`` and by
``pilworld calibrate check --images DIR``)::

    DIR/poses.json     format, rig name, board config, image size, one entry per view (below)
    DIR/000.png ...    head-camera images at the calibration resolution, one per view
    DIR/camera.yaml    the intrinsics the images were taken with (pilworld.camera_model/v1), if known

``poses.json``::

    {"format": "pilworld.handeye_recording/v1", "rig": "sim_dual_ur5e",
     "board": {<a configs/board/*.yaml mapping>}, "image_size": [1024, 1024],
     "views": [{"image": "000.png", "arm": "left", "state": [14 floats], "command": [14 floats]}, ...],
     "sim_truth": {"T_cam_base": 4x4, "T_tcp_board": {"left": 4x4}}}   # simulated rigs only

``state`` is the *measured* 14-d state (what FK uses), ``command`` the target that was sent. A user can
also assemble such a folder by hand from images and joint logs of a real rig (``command`` is optional).
"""

from __future__ import annotations

import json
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Final

import cv2
import numpy as np
import numpy.typing as npt

from calib.board import BOARD_FORMAT, ChArUcoBoard
from calib.camera_model import CameraModel
from pilworld.geometry import as_finite_array, is_rigid_transform
from pilworld.types import ARM_SIDES, STATE_DIM

__all__ = ["RECORDING_FORMAT", "RecordedView", "Recording", "SimTruth", "board_to_dict"]

FloatArray = npt.NDArray[np.float64]
UInt8Array = npt.NDArray[np.uint8]

RECORDING_FORMAT: Final = "pilworld.handeye_recording/v1"
POSES_FILE: Final = "poses.json"
CAMERA_FILE: Final = "camera.yaml"


@dataclass(frozen=True, eq=False)
class RecordedView:
    """One board view: the head-camera image and the robot state it was taken at."""

    name: str  #: image file name (``000.png``) or another identifier
    arm: str  #: the arm holding the board
    image: UInt8Array  #: ``(H, W, 3)`` RGB or ``(H, W)`` gray
    state: FloatArray  #: ``(14,)`` measured state (joint angles used for FK)
    command: FloatArray | None = None  #: ``(14,)`` the commanded target, if known

    def __post_init__(self) -> None:
        if self.arm not in ARM_SIDES:
            raise ValueError(f"view {self.name!r}: arm must be one of {', '.join(ARM_SIDES)}, got {self.arm!r}")
        state = as_finite_array(self.state, f"view {self.name!r} state", (STATE_DIM,))
        if state.shape != (STATE_DIM,):
            raise ValueError(f"view {self.name!r}: state must have shape ({STATE_DIM},), got {state.shape}")
        object.__setattr__(self, "state", state)
        if self.command is not None:
            object.__setattr__(self, "command", as_finite_array(self.command, f"view {self.name!r} command", (14,)))
        img = np.asarray(self.image)
        if img.dtype != np.uint8 or img.ndim not in (2, 3) or (img.ndim == 3 and img.shape[2] != 3):
            raise ValueError(
                f"view {self.name!r}: image must be uint8 (H, W) or (H, W, 3), got {img.dtype} {img.shape}"
            )

    @property
    def image_size(self) -> tuple[int, int]:
        return int(self.image.shape[1]), int(self.image.shape[0])

    def gray(self) -> UInt8Array:
        if self.image.ndim == 2:
            return self.image
        return np.asarray(cv2.cvtColor(self.image, cv2.COLOR_RGB2GRAY), dtype=np.uint8)


@dataclass(frozen=True, eq=False)
class SimTruth:
    """The ground truth of a simulated rig: the head camera pose and each board mount."""

    T_cam_base: FloatArray  #: ``(4, 4)`` rig frame → camera frame
    T_tcp_board: dict[str, FloatArray]  #: per arm, ``(4, 4)`` board frame → TCP frame


def _matrix(value: Any, name: str) -> FloatArray:
    arr = np.asarray(value, dtype=np.float64)
    if arr.shape != (4, 4) or not np.isfinite(arr).all() or not is_rigid_transform(arr, atol=1e-6):
        raise ValueError(f"{name}: expected a rigid 4x4 transform, got {value!r}")
    return arr


def board_to_dict(board: ChArUcoBoard) -> dict[str, Any]:
    """The ``configs/board/*.yaml`` mapping of ``board``."""
    return {
        "format": BOARD_FORMAT,
        "name": board.name,
        "squares_x": board.squares_x,
        "squares_y": board.squares_y,
        "square_length_m": board.square_length_m,
        "marker_length_m": board.marker_length_m,
        "dictionary": board.dictionary,
        "legacy_pattern": board.legacy_pattern,
        "margin_m": board.margin_m,
    }


@dataclass(frozen=True, eq=False)
class Recording:
    """A set of hand-eye views with the board, the intrinsics (if known) and, for a simulated rig, the truth."""

    rig: str
    board: ChArUcoBoard
    views: tuple[RecordedView, ...]
    camera: CameraModel | None = None  #: intrinsics at the image resolution (its T_cam_base is not used)
    truth: SimTruth | None = None
    extra: dict[str, Any] = field(default_factory=dict)  #: free-form metadata kept in poses.json

    def arms(self) -> tuple[str, ...]:
        return tuple(side for side in ARM_SIDES if any(v.arm == side for v in self.views))

    def for_arm(self, arm: str) -> tuple[RecordedView, ...]:
        return tuple(v for v in self.views if v.arm == arm)

    def save(self, folder: str | Path) -> Path:
        """Write the folder (images as PNG, states as JSON); returns the path of ``poses.json``."""
        out = Path(folder)
        out.mkdir(parents=True, exist_ok=True)
        entries = []
        for i, view in enumerate(self.views):
            name = f"{i:03d}.png"
            image = view.image if view.image.ndim == 2 else cv2.cvtColor(view.image, cv2.COLOR_RGB2BGR)
            if not cv2.imwrite(str(out / name), image):
                raise OSError(f"could not write {out / name}")
            entry: dict[str, Any] = {"image": name, "arm": view.arm, "state": view.state.tolist()}
            if view.command is not None:
                entry["command"] = view.command.tolist()
            entries.append(entry)
        sizes = {v.image_size for v in self.views}
        doc: dict[str, Any] = {
            "format": RECORDING_FORMAT,
            "rig": self.rig,
            "board": board_to_dict(self.board),
            "image_size": list(sizes.pop()) if len(sizes) == 1 else None,
            "views": entries,
        }
        if self.truth is not None:
            doc["sim_truth"] = {
                "T_cam_base": self.truth.T_cam_base.tolist(),
                "T_tcp_board": {arm: T.tolist() for arm, T in self.truth.T_tcp_board.items()},
            }
        doc.update({k: v for k, v in self.extra.items() if k not in doc})
        if self.camera is not None:
            self.camera.to_yaml(out / CAMERA_FILE)
        path = out / POSES_FILE
        path.write_text(json.dumps(doc, indent=1) + "\n", encoding="utf-8")
        return path

    @classmethod
    def load(cls, folder: str | Path) -> Recording:
        """Read a folder written by :meth:`save` (or by hand); errors name the file and the entry."""
        root = Path(folder)
        path = root / POSES_FILE
        if not root.is_dir():
            raise FileNotFoundError(f"recording folder not found: {root}")
        if not path.is_file():
            raise FileNotFoundError(f"{root}: no {POSES_FILE} (expected a folder written by --save)")
        try:
            doc = json.loads(path.read_text(encoding="utf-8"))
        except json.JSONDecodeError as exc:
            raise ValueError(f"{path}: not valid JSON: {exc}") from exc
        if not isinstance(doc, Mapping) or doc.get("format") != RECORDING_FORMAT:
            got = doc.get("format") if isinstance(doc, Mapping) else type(doc).__name__
            raise ValueError(f"{path}: field 'format': expected {RECORDING_FORMAT!r}, got {got!r}")
        board = ChArUcoBoard.from_dict(doc.get("board", {}), source=f"{path} board")
        raw_views = doc.get("views")
        if not isinstance(raw_views, Sequence) or not raw_views:
            raise ValueError(f"{path}: field 'views': expected a non-empty list of views")
        views = []
        for i, entry in enumerate(raw_views):
            where = f"{path} views[{i}]"
            if not isinstance(entry, Mapping) or not {"image", "arm", "state"} <= set(entry):
                raise ValueError(f"{where}: expected a mapping with image, arm and state")
            file = root / str(entry["image"])
            image = cv2.imread(str(file), cv2.IMREAD_COLOR) if file.is_file() else None
            if image is None:
                raise ValueError(f"{where}: cannot read image {file}")
            try:
                views.append(
                    RecordedView(
                        name=str(entry["image"]),
                        arm=str(entry["arm"]),
                        image=np.asarray(cv2.cvtColor(image, cv2.COLOR_BGR2RGB), dtype=np.uint8),
                        state=np.asarray(entry["state"], dtype=np.float64),
                        command=None if entry.get("command") is None else np.asarray(entry["command"], np.float64),
                    )
                )
            except (TypeError, ValueError) as exc:
                raise ValueError(f"{where}: {exc}") from exc
        camera = CameraModel.from_yaml(root / CAMERA_FILE) if (root / CAMERA_FILE).is_file() else None
        truth = None
        if isinstance(doc.get("sim_truth"), Mapping):
            st = doc["sim_truth"]
            truth = SimTruth(
                T_cam_base=_matrix(st.get("T_cam_base"), f"{path} sim_truth.T_cam_base"),
                T_tcp_board={
                    str(a): _matrix(T, f"{path} sim_truth.T_tcp_board.{a}")
                    for a, T in st.get("T_tcp_board", {}).items()
                },
            )
        known = {"format", "rig", "board", "image_size", "views", "sim_truth"}
        return cls(
            rig=str(doc.get("rig", "")),
            board=board,
            views=tuple(views),
            camera=camera,
            truth=truth,
            extra={k: v for k, v in doc.items() if k not in known},
        )
