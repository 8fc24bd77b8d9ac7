"""A ChArUco board held up to a camera by a person: a free-floating (mocap) plate in the simulated scene.

Intrinsics are calibrated from a board waved in front of the camera, with no robot involved. On the fake
rig the person is simulated: :class:`HandBoard` adds a visual-only plate on a MuJoCo *mocap* body, which
:meth:`simrig.robot.SimRobot.hold_board` places anywhere (or parks out of sight) without touching the
physics. The plate's mesh is the board frame itself (its front-face vertices are the page corners, with
explicit texture coordinates, as in :mod:`simrig.board_mount`), so a board pose ``T_rig_board`` set
on the mocap body puts every corner exactly where the board model says.

:func:`presentation_poses` plans what a careful person shows a camera: the board at several distances,
centred on every part of the image, tilted 0-50° towards every side and turned about its normal.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from functools import cached_property
from typing import Final

import numpy as np
import numpy.typing as npt

from calib.board import ChArUcoBoard
from calib.camera_model import CameraModel
from calib.rotations import rotation_exp
from simrig.board_plate import board_texture_png, plate_asset_xml

__all__ = ["HAND_BOARD_TEXTURE_FILE", "PARKED", "HandBoard", "presentation_poses"]

FloatArray = npt.NDArray[np.float64]

HAND_BOARD_TEXTURE_FILE: Final = "pilworld_hand_board.png"
_NAME: Final = "hand_calibration_board"
#: Where the board waits while nobody holds it up: far below the table, out of every camera's view.
PARKED: Final = np.array([0.0, 0.0, -5.0])


@dataclass(frozen=True, eq=False)
class HandBoard:
    """A board on a mocap body (visual only); its pose is set at run time (``SimRobot.hold_board``)."""

    board: ChArUcoBoard
    texture_ppm: float = 4000.0  #: texture resolution, pixels per metre of the page
    thickness_m: float = 0.004

    def __post_init__(self) -> None:
        for name in ("texture_ppm", "thickness_m"):
            value = float(getattr(self, name))
            if not (math.isfinite(value) and value > 0.0):
                raise ValueError(f"hand board {name}: expected a positive number, got {getattr(self, name)!r}")
        w, h = self.board.page_size_m
        if max(w, h) * self.texture_ppm > 8192:
            raise ValueError(f"hand board texture_ppm: a {w * 1e3:.0f} mm page exceeds 8192 texels; lower it")

    @property
    def body(self) -> str:
        """The mocap body's name."""
        return _NAME

    @cached_property
    def texture_png(self) -> bytes:
        return board_texture_png(self.board, self.texture_ppm, "hand board")

    def assets(self) -> dict[str, bytes]:
        return {HAND_BOARD_TEXTURE_FILE: self.texture_png}

    def asset_xml(self) -> str:
        """Texture, material and the plate mesh in the board frame (the mocap body's frame)."""
        return plate_asset_xml(self.board, self.thickness_m, lambda p: p, _NAME, HAND_BOARD_TEXTURE_FILE)

    def body_xml(self) -> str:
        """The mocap body with the plate, for the world body; parked out of sight."""
        x, y, z = (float(v) for v in PARKED)
        return (
            f'<body name="{_NAME}" mocap="true" pos="{x} {y} {z}">'
            f'<geom name="{_NAME}" type="mesh" mesh="{_NAME}" material="{_NAME}" contype="0" conaffinity="0" '
            'group="0"/></body>'
        )


def presentation_poses(
    camera: CameraModel,
    board: ChArUcoBoard,
    count: int,
    *,
    seed: int = 0,
    distance_m: tuple[float, float] = (0.5, 0.8),
    max_tilt_deg: float = 50.0,
    min_inside: float = 0.6,
) -> list[FloatArray]:
    """``count`` board poses ``T_rig_board`` a person would show ``camera``.

    The board's centre cycles through a 4 × 4 grid of image regions, out to the image's edges, at distances
    in ``distance_m``; its face is tilted up to ``max_tilt_deg`` off the line of sight towards a random side
    and turned ±45° about its normal. Near the edges the board may stick out of the image, as when a person
    sweeps it there (the corners at the image's edges are what pin distortion and the principal point down);
    a pose with fewer than ``min_inside`` of its chessboard corners in the image is redrawn.
    """
    if count < 1:
        raise ValueError(f"count: expected at least 1 pose, got {count}")
    rng = np.random.default_rng(seed)
    T_base_cam = np.linalg.inv(np.asarray(camera.T_cam_base, dtype=np.float64))
    K_inv = np.linalg.inv(np.asarray(camera.K, dtype=np.float64))
    w, h = board.size_m
    centre_board = np.array([w / 2.0, h / 2.0, 0.0])
    corners = board.corner_points()
    cells = [(u, v) for v in (0.14, 0.38, 0.62, 0.86) for u in (0.14, 0.38, 0.62, 0.86)]
    poses: list[FloatArray] = []
    tries = 0
    while len(poses) < count:
        tries += 1
        if tries > 200 * count:
            raise ValueError(
                f"presentation_poses: could not fit {count} board poses inside the {camera.width}x{camera.height} "
                f"image at {distance_m[0]}-{distance_m[1]} m (the board is {w * 1e3:.0f} mm wide)"
            )
        u, v = cells[len(poses) % len(cells)]
        u += rng.uniform(-0.06, 0.06)
        v += rng.uniform(-0.06, 0.06)
        ray = K_inv @ np.array([u * (camera.width - 1), v * (camera.height - 1), 1.0])
        ray /= np.linalg.norm(ray)
        d = rng.uniform(*distance_m)
        centre_cam = ray * d
        # Board z points into the board, away from the camera: a fronto-parallel board has z = the ray.
        tilt = math.radians(rng.uniform(0.0, max_tilt_deg))
        axis_angle = rng.uniform(0.0, 2 * math.pi)
        side = np.cross(ray, [0.0, 1.0, 0.0])
        side /= np.linalg.norm(side)
        up = np.cross(side, ray)
        axis = math.cos(axis_angle) * side + math.sin(axis_angle) * up
        R_face = rotation_exp(axis * tilt)
        spin = rotation_exp(ray * math.radians(rng.uniform(-45.0, 45.0)))
        x0 = side
        z0 = ray
        R0 = np.stack([x0, np.cross(z0, x0), z0], axis=1)
        R_cam_board = R_face @ spin @ R0
        T_cam_board = np.eye(4)
        T_cam_board[:3, :3] = R_cam_board
        T_cam_board[:3, 3] = centre_cam - R_cam_board @ centre_board
        T_base_board = T_base_cam @ T_cam_board
        _, visible = camera.project(corners @ T_base_board[:3, :3].T + T_base_board[:3, 3])
        if visible.mean() < min_inside:
            continue
        poses.append(T_base_board)
    return poses
