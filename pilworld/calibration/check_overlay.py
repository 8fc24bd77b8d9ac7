"""Overlay images of a calibration check, for a person to judge.

See docs/calibration.md, "4. Check" and "Wrist cameras (eye-in-hand)".

Head camera (:func:`draw_overlay`): a cross per gripper at its FK-projected point (left red, right blue,
as in the control video), a circle at the truth when it is known, and the FK-predicted board corners as
dots. Wrist camera (:func:`draw_wrist_overlay`): the detected corners as green circles and the FK-projected
ones as red crosses, with a label. Points are drawn with 4 fractional bits, so sub-pixel errors show.
"""

from __future__ import annotations

from typing import Final

import cv2
import numpy as np
import numpy.typing as npt

from pilworld.types import ARM_SIDES

__all__ = ["ARM_COLORS_RGB", "DETECTED_RGB", "PROJECTED_RGB", "draw_overlay", "draw_wrist_overlay"]

FloatArray = npt.NDArray[np.float64]
UInt8Array = npt.NDArray[np.uint8]

ARM_COLORS_RGB: Final = {"left": (230, 40, 40), "right": (40, 90, 230)}  #: the control video's colours
TRUTH_RGB: Final = (40, 200, 40)  #: the true gripper point: a circle
BOARD_RGB: Final = (250, 200, 0)  #: FK-predicted board corners on a head-camera view: dots
DETECTED_RGB: Final = (40, 200, 40)  #: detected corners: green circles
PROJECTED_RGB: Final = (230, 40, 40)  #: FK-projected corners: red crosses
_SHIFT: Final = 4  # fractional bits of the drawn coordinates
_ONE: Final = 1 << _SHIFT


def _canvas(image: UInt8Array) -> UInt8Array:
    """A writable RGB copy of ``image`` (gray is repeated into three channels)."""
    return np.ascontiguousarray(image if image.ndim == 3 else np.repeat(image[..., None], 3, axis=2)).copy()


def _fixed(uv: npt.ArrayLike) -> npt.NDArray[np.int_]:
    return np.round(np.asarray(uv) * _ONE).astype(int)


def _cross(out: UInt8Array, p: npt.NDArray[np.int_], size: int, color: tuple[int, int, int], thick: int) -> None:
    for d in ((size, size), (size, -size)):
        a = (int(p[0] - d[0] * _ONE), int(p[1] - d[1] * _ONE))
        b = (int(p[0] + d[0] * _ONE), int(p[1] + d[1] * _ONE))
        cv2.line(out, a, b, color, thick, cv2.LINE_AA, _SHIFT)


def _circle(out: UInt8Array, p: npt.NDArray[np.int_], radius: int, color: tuple[int, int, int], thick: int) -> None:
    cv2.circle(out, (int(p[0]), int(p[1])), radius * _ONE, color, thick, cv2.LINE_AA, _SHIFT)


def draw_overlay(
    image: UInt8Array,
    uv: FloatArray,
    visible: npt.NDArray[np.bool_],
    uv_true: FloatArray | None = None,
    board_uv: FloatArray | None = None,
) -> UInt8Array:
    """``image`` (RGB) with a cross per gripper at ``uv`` ``(2, 2)``, a circle at the truth and board dots."""
    out = _canvas(image)
    size = max(4, round(min(out.shape[:2]) / 40))
    thick = max(1, round(min(out.shape[:2]) / 400))
    for k, side in enumerate(ARM_SIDES):
        if not visible[k]:
            continue
        _cross(out, _fixed(uv[k]), size, ARM_COLORS_RGB[side], thick)
        if uv_true is not None:
            _circle(out, _fixed(uv_true[k]), size, TRUTH_RGB, thick)
    if board_uv is not None:
        for p in _fixed(board_uv):
            _circle(out, p, max(1, size // 3), BOARD_RGB, -1)
    return out


def draw_wrist_overlay(image: UInt8Array, detected: FloatArray, projected: FloatArray, label: str = "") -> UInt8Array:
    """``image`` (RGB) with the detected corners (green circles), the projected ones (red crosses) and a label."""
    out = _canvas(image)
    size = max(3, round(min(out.shape[:2]) / 80))
    thick = max(1, round(min(out.shape[:2]) / 500))
    for p in _fixed(detected):
        _circle(out, p, size, DETECTED_RGB, thick)
    for p in _fixed(projected):
        _cross(out, p, size, PROJECTED_RGB, thick)
    if label:
        scale = max(0.35, min(out.shape[:2]) / 1200)
        cv2.putText(
            out, label, (6, 6 + round(22 * scale)), cv2.FONT_HERSHEY_SIMPLEX, scale, (255, 255, 255), 1, cv2.LINE_AA
        )
    return out
