"""A ChArUco board lying flat on the simulated table, for eye-in-hand calibration of the wrist cameras.

The board is a thin, visual-only plate (``contype = conaffinity = 0``) in the world body, its printed
face ``face_height_m`` above the table top (above the tasks' flat slot outlines), so the ground truth is
exact: ``T_rig_board`` (board-frame points → rig frame) is what :class:`TableBoard` says it is. Board z
("into the board", OpenCV's board frame) points down into the table; board x runs along ``yaw_deg`` from
the rig's +x axis.

Texture mapping as in :mod:`simrig.board_mount`: a mesh whose front-face vertices are the page
corners, with explicit ``texcoord`` of the page image from :meth:`calib.board.ChArUcoBoard.render`, so a
texel edge lies exactly at its board-frame position. The PNG reaches MuJoCo through the ``assets``
mapping (:meth:`TableBoard.assets`), under a name of its own, so it can coexist with a gripper board.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from functools import cached_property
from typing import Final

import numpy as np
import numpy.typing as npt

from calib.board import ChArUcoBoard
from pilworld.geometry import is_rigid_transform
from pilworld.types import ARM_SIDES
from simrig.board_plate import board_texture_png, page_corners_board, plate_asset_xml

__all__ = ["TABLE_BOARD_TEXTURE_FILE", "TableBoard"]

FloatArray = npt.NDArray[np.float64]

#: Name of the table board's texture in the ``assets`` mapping passed to MuJoCo.
TABLE_BOARD_TEXTURE_FILE: Final = "pilworld_table_board.png"
_NAME: Final = "table_calibration_board"
#: Default board centres (rig frame, x and y) for calibrating each arm's wrist camera: beside the
#: tasks' object area (cubes within |y| <= 0.26 m), within easy reach of that arm.
DEFAULT_CENTRE: Final = {"left": (-0.05, 0.37), "right": (-0.05, -0.37)}
# Two triangles per face of the plate's box: front (seen from above), back, then the four sides.


@dataclass(frozen=True, eq=False)
class TableBoard:
    """A ChArUco board fixed flat on the table (visual only); the simulator's eye-in-hand ground truth."""

    board: ChArUcoBoard  #: the board printed on the plate (its page, margin included, is the plate's face)
    #: ``(4, 4)`` rigid transform mapping board-frame points (OpenCV board frame, metres) into the rig frame
    T_rig_board: FloatArray = field(repr=False)
    texture_ppm: float = 4000.0  #: texture resolution, pixels per metre of the page (0.25 mm texels)
    thickness_m: float = 0.004  #: plate thickness below the printed face

    def __post_init__(self) -> None:
        T = np.array(self.T_rig_board, dtype=np.float64)
        if T.shape != (4, 4) or not is_rigid_transform(T):
            raise ValueError(f"table board T_rig_board: expected a rigid 4x4 transform, got {T.tolist()}")
        T.flags.writeable = False
        object.__setattr__(self, "T_rig_board", T)
        for name in ("texture_ppm", "thickness_m"):
            value = float(getattr(self, name))
            if not (math.isfinite(value) and value > 0.0):
                raise ValueError(f"table board {name}: expected a positive number, got {getattr(self, name)!r}")
            object.__setattr__(self, name, value)
        w, h = self.board.page_size_m
        if max(w, h) * self.texture_ppm > 8192:
            raise ValueError(
                f"table board texture_ppm: a {w * 1e3:.0f} x {h * 1e3:.0f} mm page at {self.texture_ppm:g} px/m "
                "exceeds 8192 texels; lower texture_ppm"
            )

    @classmethod
    def flat(
        cls,
        board: ChArUcoBoard,
        centre_xy: tuple[float, float],
        yaw_deg: float = 0.0,
        face_height_m: float = 0.004,
    ) -> TableBoard:
        """The board face up on the table, its chessboard centred at ``centre_xy``, x turned ``yaw_deg`` from +x."""
        if not (math.isfinite(face_height_m) and face_height_m > 0.0):
            raise ValueError(f"table board face_height_m: expected metres > 0, got {face_height_m!r}")
        cx, cy = (float(v) for v in centre_xy)
        if not (math.isfinite(cx) and math.isfinite(cy)):
            raise ValueError(f"table board centre_xy: expected two finite metres, got {centre_xy!r}")
        yaw = math.radians(yaw_deg)
        x = np.array([math.cos(yaw), math.sin(yaw), 0.0])
        z = np.array([0.0, 0.0, -1.0])  # into the board: down
        R = np.stack([x, np.cross(z, x), z], axis=1)
        w, h = board.size_m
        T = np.eye(4)
        T[:3, :3] = R
        T[:3, 3] = np.array([cx, cy, face_height_m]) - R @ np.array([w / 2.0, h / 2.0, 0.0])
        return cls(board=board, T_rig_board=T, thickness_m=face_height_m)

    @classmethod
    def for_arm(cls, board: ChArUcoBoard, arm: str) -> TableBoard:
        """The default board for calibrating ``arm``'s wrist camera (:data:`DEFAULT_CENTRE`)."""
        if arm not in ARM_SIDES:
            raise ValueError(f"table board arm: expected one of {', '.join(ARM_SIDES)}, got {arm!r}")
        return cls.flat(board, DEFAULT_CENTRE[arm])

    # ------------------------------------------------------------------ geometry

    def page_corners_board(self) -> FloatArray:
        """``(4, 3)`` page corners (margin included), board frame."""
        return page_corners_board(self.board)

    def to_rig(self, points: npt.ArrayLike) -> FloatArray:
        """Board-frame points ``(n, 3)`` → rig frame."""
        p = np.asarray(points, dtype=np.float64).reshape(-1, 3)
        out: FloatArray = p @ self.T_rig_board[:3, :3].T + self.T_rig_board[:3, 3]
        return out

    def centre_rig(self) -> FloatArray:
        """``(3,)`` centre of the chessboard in the rig frame."""
        w, h = self.board.size_m
        out: FloatArray = self.to_rig([[w / 2.0, h / 2.0, 0.0]])[0]
        return out

    # ------------------------------------------------------------------ MJCF

    @cached_property
    def texture_png(self) -> bytes:
        """The page (board and margin) as a grayscale PNG, area-antialiased."""
        return board_texture_png(self.board, self.texture_ppm, "table board")

    def assets(self) -> dict[str, bytes]:
        """The ``assets`` mapping for ``mujoco.MjModel.from_xml_string``."""
        return {TABLE_BOARD_TEXTURE_FILE: self.texture_png}

    def asset_xml(self) -> str:
        """The ``<asset>`` children: texture, material and the textured plate mesh (rig-frame vertices)."""
        return plate_asset_xml(self.board, self.thickness_m, self.to_rig, _NAME, TABLE_BOARD_TEXTURE_FILE)

    def geom_xml(self) -> str:
        """The plate geom, for the world body."""
        return (
            f'<geom name="{_NAME}" type="mesh" mesh="{_NAME}" material="{_NAME}" contype="0" conaffinity="0" '
            'group="0"/>'
        )
