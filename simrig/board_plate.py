"""The textured plate a simulated ChArUco board is printed on: its PNG texture and its MJCF assets.

Shared by the board held in a gripper (:mod:`simrig.board_mount`, head-camera hand-eye) and the
board lying on the table (:mod:`simrig.table_board`, wrist-camera eye-in-hand). The plate is a
box mesh whose front-face vertices are the page corners with explicit texture coordinates, so a texel
edge lies exactly at its board-frame position (see board_mount's docstring for the accuracy measured).
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Final

import cv2
import numpy as np
import numpy.typing as npt

from calib.board import ChArUcoBoard

FloatArray = npt.NDArray[np.float64]

#: Faces of the plate's 8 vertices (front 0–3 = the page corners, back 4–7 behind them): the front faces wind
#: counter-clockwise seen from the printed side (normal −z_board); the back and the thin sides follow.
PLATE_FACES: Final = "0 2 1 0 3 2 4 5 6 4 6 7 0 1 5 0 5 4 1 2 6 1 6 5 2 3 7 2 7 6 3 0 4 3 4 7"


def _f(values: npt.ArrayLike) -> str:
    return " ".join(f"{float(v):.12g}" for v in np.asarray(values, dtype=np.float64).reshape(-1))


def page_corners_board(board: ChArUcoBoard) -> FloatArray:
    """``(4, 3)`` page corners (margin included) in the board frame."""
    m = board.margin_m
    w, h = board.size_m
    return np.array([[-m, -m, 0.0], [w + m, -m, 0.0], [w + m, h + m, 0.0], [-m, h + m, 0.0]])


def board_texture_png(board: ChArUcoBoard, pixels_per_m: float, what: str) -> bytes:
    """The page (board and margin) as a grayscale PNG, area-antialiased so edges sit at sub-texel accuracy."""
    image = board.render(pixels_per_m, antialias=True)
    ok, encoded = cv2.imencode(".png", image)
    if not ok:  # pragma: no cover - OpenCV always encodes a uint8 image
        raise OSError(f"could not encode the {what} texture")
    return bytes(encoded.tobytes())


def plate_asset_xml(
    board: ChArUcoBoard,
    thickness_m: float,
    to_parent: Callable[[FloatArray], FloatArray],
    name: str,
    texture_file: str,
) -> str:
    """``<asset>`` children: texture, an unlit-looking material and the plate mesh in its parent body's frame.

    ``to_parent`` maps board-frame points ``(n, 3)`` into the frame of the body that carries the geom.
    """
    m = board.margin_m
    page_w, page_h = board.page_size_m
    front = page_corners_board(board)
    back = front + np.array([0.0, 0.0, thickness_m])  # behind the face (board z points into it)
    verts = to_parent(np.concatenate([front, back]))
    uv = (front[:, :2] + m) / np.array([page_w, page_h])
    texcoord = np.concatenate([uv, uv])  # the thin sides repeat the edge texels
    return (
        f'<texture name="{name}" type="2d" file="{texture_file}"/>'
        f'<material name="{name}" texture="{name}" rgba="1 1 1 1" specular="0" shininess="0" emission="0.35"/>'
        f'<mesh name="{name}" vertex="{_f(verts)}" texcoord="{_f(texcoord)}" face="{PLATE_FACES}"/>'
    )
