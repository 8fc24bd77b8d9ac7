"""A ChArUco board rigidly mounted on one gripper of the simulated rig, for hand-eye calibration.

The board is a thin, visual-only plate (``contype = conaffinity = 0``, negligible mass) in the arm's
``{side}_tcp_frame`` body, i.e. rigidly attached to the TCP frame, so the ground truth is exact:
``T_tcp_board`` (board-frame points → TCP frame) is what :class:`BoardMount` says it is.

Default placement (:meth:`BoardMount.beside_tcp`): the board plane is perpendicular to the tool axis at
the TCP, its face normal pointing back along the tool axis (towards the camera when the tool points
down), board x along tool x and board y along tool y (so ``R_tcp_board = I``: board z, "into the board",
is the tool z). The printed page starts ``gap_m`` beside the tool axis along tool +x, so the palm and the
opening fingers (which move along tool y) never cover it.

Texture mapping: the plate is a mesh whose front-face vertices are the page corners with explicit
``texcoord`` ``(u, v) = ((x + margin) / page_width, (y + margin) / page_height)`` of the board image from
:meth:`calib.board.ChArUcoBoard.render` (row 0 at ``v = 0``, as MuJoCo uploads PNG rows). A texel edge
then lies exactly at its board-frame position; rendering the board with the rig's head camera and
detecting its corners agrees with the projection of the known 3-D corners to ~0.05 px RMS at 1024×1024
(``tests/pilworld/calibration/test_board_mount.py``). The PNG goes to MuJoCo through the ``assets``
mapping of ``MjModel.from_xml_string`` (:meth:`BoardMount.assets`), never through a temporary file.
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

__all__ = ["BOARD_TEXTURE_FILE", "BoardMount"]

FloatArray = npt.NDArray[np.float64]

#: Name of the board texture in the ``assets`` mapping passed to MuJoCo.
BOARD_TEXTURE_FILE: Final = "pilworld_calibration_board.png"
_MESH_NAME: Final = "calibration_board"
_BRACKET_RADIUS: Final = 0.005  # m


def _f(values: npt.ArrayLike) -> str:
    return " ".join(f"{float(v):.12g}" for v in np.asarray(values, dtype=np.float64).reshape(-1))


@dataclass(frozen=True, eq=False)
class BoardMount:
    """A ChArUco board on one arm's TCP frame (visual only); the simulator's hand-eye ground truth."""

    board: ChArUcoBoard  #: the board printed on the plate (its page, margin included, is the plate's face)
    arm: str  #: "left" or "right": the arm whose TCP frame carries the board
    #: ``(4, 4)`` rigid transform mapping board-frame points (OpenCV board frame, metres) into the TCP frame
    T_tcp_board: FloatArray = field(repr=False)
    #: texture resolution, pixels per metre of the page (4000 = 0.25 mm texels: finer than a 1024² render
    #: needs, MuJoCo's mipmaps handle the minification)
    texture_ppm: float = 4000.0
    thickness_m: float = 0.003  #: plate thickness behind the printed face

    def __post_init__(self) -> None:
        if self.arm not in ARM_SIDES:
            raise ValueError(f"board mount arm: expected one of {', '.join(ARM_SIDES)}, got {self.arm!r}")
        T = np.array(self.T_tcp_board, dtype=np.float64)
        if T.shape != (4, 4) or not is_rigid_transform(T):
            raise ValueError(f"board mount T_tcp_board: expected a rigid 4x4 transform, got {T.tolist()}")
        T.flags.writeable = False
        object.__setattr__(self, "T_tcp_board", T)
        for name in ("texture_ppm", "thickness_m"):
            value = float(getattr(self, name))
            if not (math.isfinite(value) and value > 0.0):
                raise ValueError(f"board mount {name}: expected a positive number, got {getattr(self, name)!r}")
            object.__setattr__(self, name, value)
        w, h = self.board.page_size_m
        if max(w, h) * self.texture_ppm > 8192:
            raise ValueError(
                f"board mount texture_ppm: a {w * 1e3:.0f} x {h * 1e3:.0f} mm page at {self.texture_ppm:g} px/m "
                "exceeds 8192 texels; lower texture_ppm"
            )

    @classmethod
    def beside_tcp(cls, board: ChArUcoBoard, arm: str, gap_m: float = 0.07, plate_z_m: float = 0.0) -> BoardMount:
        """The default mount: board plane at ``plate_z_m`` along the tool axis, page from ``gap_m`` along tool +x.

        ``R_tcp_board = I`` (see the module docstring); the page is centred on the tool x axis.
        """
        if not (math.isfinite(gap_m) and gap_m >= 0.0):
            raise ValueError(f"board mount gap_m: expected metres >= 0, got {gap_m!r}")
        _, page_h = board.page_size_m
        T = np.eye(4)
        # Board origin = top-left chessboard corner = page corner + (margin, margin).
        T[:3, 3] = (gap_m + board.margin_m, -page_h / 2.0 + board.margin_m, plate_z_m)
        return cls(board=board, arm=arm, T_tcp_board=T)

    # ------------------------------------------------------------------ geometry

    def page_corners_board(self) -> FloatArray:
        """``(4, 3)`` page corners (margin included), board frame: top-left, top-right, bottom-right, bottom-left."""
        return page_corners_board(self.board)

    def page_corners_tcp(self) -> FloatArray:
        """``(4, 3)`` page corners in the TCP frame (metres)."""
        return self._to_tcp(self.page_corners_board())

    def corner_points_tcp(self) -> FloatArray:
        """``(n_corners, 3)`` chessboard corners in the TCP frame, row ``k`` = corner id ``k``."""
        return self._to_tcp(self.board.corner_points())

    def _to_tcp(self, points: FloatArray) -> FloatArray:
        out: FloatArray = points @ self.T_tcp_board[:3, :3].T + self.T_tcp_board[:3, 3]
        return out

    # ------------------------------------------------------------------ MJCF

    @cached_property
    def texture_png(self) -> bytes:
        """The page (board and margin) as a grayscale PNG, area-antialiased so edges sit at sub-texel accuracy."""
        return board_texture_png(self.board, self.texture_ppm, "board")

    def assets(self) -> dict[str, bytes]:
        """The ``assets`` mapping for ``mujoco.MjModel.from_xml_string``."""
        return {BOARD_TEXTURE_FILE: self.texture_png}

    def asset_xml(self) -> str:
        """The ``<asset>`` children: the texture, an unlit-looking material and the textured plate mesh."""
        return plate_asset_xml(self.board, self.thickness_m, self._to_tcp, _MESH_NAME, BOARD_TEXTURE_FILE)

    def geom_xml(self) -> str:
        """The plate geom and its bracket, for the ``{arm}_tcp_frame`` body (coordinates in the TCP frame).

        The bracket, a thin rod from the TCP (between the fingertips) to the middle of the page's near
        edge, runs wholly behind the printed face, so it can never hide a corner.
        """
        _, h = self.board.size_m
        edge = self._to_tcp(np.array([[-self.board.margin_m, h / 2.0, self.thickness_m + _BRACKET_RADIUS]]))[0]
        return (
            f'<geom name="{self.arm}_calibration_board" type="mesh" mesh="{_MESH_NAME}" material="{_MESH_NAME}" '
            'contype="0" conaffinity="0" mass="1e-4"/>'
            f'<geom name="{self.arm}_calibration_bracket" type="capsule" fromto="0 0 0 {_f(edge)}" '
            f'size="{_BRACKET_RADIUS}" rgba="0.45 0.46 0.48 1" contype="0" conaffinity="0" mass="1e-4"/>'
        )
