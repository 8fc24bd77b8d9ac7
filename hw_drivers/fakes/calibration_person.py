"""The person at the fake rig during a calibration: mounts the board, or holds it up to the head camera.

At a real rig an operator clamps the ChArUco board to a gripper before a hand-eye calibration, and waves
it in front of the camera for the intrinsics. On the fake rig the simulator stands in for that person
(requests of :class:`hw_drivers.fakes.rig.FakeRig`):

* :func:`place_board` — the board on the ``left`` or ``right`` gripper (:class:`BoardMount`, the reference
  bracket: 70 mm beside the tool axis), in a person's ``hand`` (:class:`HandBoard`), or put away (``None``);
* :class:`BoardPresenter` — the person holds the board still at one pose after another
  (:func:`~simrig.hand_board.presentation_poses` for the head camera at its streamed size), each for
  ``hold_s`` seconds, like someone following a calibration tool's prompts; it stops after the last pose
  (the board is then lowered out of view) or when asked.

The truth a test compares with: the camera streams the rig's head camera at ``stream_sizes`` (its
intrinsics are ``rig.head_camera_model.resized(width, height)``), and the mount is
``BoardMount.beside_tcp(board, side).T_tcp_board``.
"""

from __future__ import annotations

import functools
import threading
from pathlib import Path
from typing import Any

from calib.board import ChArUcoBoard
from calib.camera_model import CameraModel
from hw_drivers.fakes.backend import SimBackend
from pilworld.config.rig import RigConfig
from simrig.board_mount import BoardMount
from simrig.hand_board import HandBoard, presentation_poses

WHERE = ("left", "right", "hand")


def streamed_head_camera(rig: RigConfig) -> CameraModel:
    """The head camera as the fake streams it: the rig's designed camera at its ``stream_sizes`` entry."""
    cam = rig.head_camera_model
    fake = rig.hardware.fake if rig.hardware is not None else None
    size = fake.stream_sizes.get(cam.name or "cam_high") if fake is not None else None
    return cam if size is None else cam.resized(size.width, size.height)


def place_board(backend: SimBackend, board_file: str | Path, where: str | None) -> None:
    """Mount the board on a gripper, hold it in a hand (parked out of view until presented), or remove it."""
    if where is not None and where not in WHERE:
        raise ValueError(f"board: expected one of {WHERE} or None, got {where!r}")
    board = ChArUcoBoard.from_yaml(board_file)

    def place(robot: Any) -> None:
        if where in ("left", "right"):
            robot.set_boards(board_mount=BoardMount.beside_tcp(board, where))
        elif where == "hand":
            robot.set_boards(hand_board=HandBoard(board))
        else:
            robot.set_boards()

    backend.call(place, moves_world=True)


def _hold(robot: Any, T: Any) -> None:
    robot.hold_board(T)


class BoardPresenter:
    """A person holding the board up to the head camera, pose after pose (see the module docstring)."""

    def __init__(
        self, backend: SimBackend, rig: RigConfig, board_file: str | Path, *, count: int, seed: int, hold_s: float
    ) -> None:
        if hold_s <= 0:
            raise ValueError(f"hold_s: expected > 0, got {hold_s}")
        self.backend = backend
        board = ChArUcoBoard.from_yaml(board_file)
        self.poses = presentation_poses(streamed_head_camera(rig), board, count, seed=seed)
        self.hold_s = float(hold_s)
        self.shown = 0  # poses presented so far
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, name="board-presenter", daemon=True)

    def start(self) -> BoardPresenter:
        self._thread.start()
        return self

    def _run(self) -> None:
        try:
            for T in self.poses:
                if self._stop.is_set():
                    break
                self.backend.call(functools.partial(_hold, T=T))
                self.shown += 1
                if self._stop.wait(self.hold_s):
                    break
            self.backend.call(functools.partial(_hold, T=None))
        except Exception:  # the backend closed under the person: nothing left to hold the board for
            pass

    def stop(self) -> None:
        self._stop.set()
        self._thread.join(5.0)

    @property
    def running(self) -> bool:
        return self._thread.is_alive()
