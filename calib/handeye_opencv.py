"""Cross-check of our eye-to-hand solution against OpenCV's hand-eye methods, when the installed cv2 has them.

opencv-contrib 4.x has ``cv2.calibrateHandEye`` (TSAI, PARK, HORAUD, ANDREFF, DANIILIDIS) and
``cv2.calibrateRobotWorldHandEye`` (SHAH, LI); the 5.x Python wheel has neither (shared/REFERENCES.md),
and then :func:`opencv_eye_to_hand` returns an empty mapping. Both APIs are written for eye-in-hand;
the eye-to-hand mapping used here (and verified by the tests on noise-free data):

* ``calibrateHandEye``: pass base→gripper (the *inverse* of FK) in the "gripper2base" slots and
  target2cam = ``T_cam_board``; the result called "cam2gripper" is then ``T_base_cam`` (cam→base).
* ``calibrateRobotWorldHandEye`` (``cTw · wTb = cTg · gTb``): "world2cam" = ``T_cam_board`` and
  "base2gripper" = FK ``T_base_gripper``; "gripper2cam" is then ``T_cam_base`` and "base2world" is
  ``T_board_gripper``.

``method=`` is always passed by keyword: positionally it lands in an output argument and OpenCV silently
runs TSAI.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import cv2
import numpy as np
import numpy.typing as npt

from calib.handeye_mount import CameraMount
from calib.rotations import as_transforms, pose_difference, rigid
from pilworld.geometry import invert_transform

__all__ = ["OpenCvEstimate", "opencv_eye_to_hand", "opencv_hand_eye"]

FloatArray = npt.NDArray[np.float64]

_HAND_EYE = ("TSAI", "PARK", "HORAUD", "ANDREFF", "DANIILIDIS")
_ROBOT_WORLD = ("SHAH", "LI")


@dataclass(frozen=True, eq=False)
class OpenCvEstimate:
    """One OpenCV method's ``T_cam_base`` and how far it is from a reference solution."""

    method: str
    T_cam_base: FloatArray  #: of the fixed camera (for a wrist camera: ``T_cam_tcp``, see :func:`opencv_hand_eye`)
    translation_diff_m: float  #: |t - t_ref|, NaN without a reference
    rotation_diff_deg: float  #: angle of R R_refᵀ, NaN without a reference


def opencv_eye_to_hand(
    T_base_gripper: Sequence[npt.ArrayLike] | npt.ArrayLike,
    T_cam_board: Sequence[npt.ArrayLike] | npt.ArrayLike,
    reference_T_cam_base: npt.ArrayLike | None = None,
) -> dict[str, OpenCvEstimate]:
    """``T_cam_base`` from every OpenCV method available, keyed by method name (empty on OpenCV 5.x).

    Run it only on motion that passed :func:`calib.handeye.check_motion`: TSAI returns the identity
    without raising on degenerate input. A method that raises inside OpenCV is left out.
    """
    G = as_transforms(T_base_gripper, "T_base_gripper")
    C = as_transforms(T_cam_board, "T_cam_board")
    if G.shape[0] != C.shape[0]:
        raise ValueError(f"T_base_gripper and T_cam_board differ in length: {G.shape[0]} vs {C.shape[0]}")
    ref = None if reference_T_cam_base is None else np.asarray(reference_T_cam_base, dtype=np.float64)
    found: dict[str, FloatArray] = {}
    if hasattr(cv2, "calibrateHandEye"):
        base_to_gripper = invert_transform(G)
        for name in _HAND_EYE:
            try:
                R, t = cv2.calibrateHandEye(
                    list(base_to_gripper[:, :3, :3]),
                    list(base_to_gripper[:, :3, 3:]),
                    list(C[:, :3, :3]),
                    list(C[:, :3, 3:]),
                    method=getattr(cv2, f"CALIB_HAND_EYE_{name}"),
                )
            except cv2.error:
                continue
            found[name] = invert_transform(rigid(R, t))
    if hasattr(cv2, "calibrateRobotWorldHandEye"):
        for name in _ROBOT_WORLD:
            try:
                _, _, R, t = cv2.calibrateRobotWorldHandEye(
                    list(C[:, :3, :3]),
                    list(C[:, :3, 3:]),
                    list(G[:, :3, :3]),
                    list(G[:, :3, 3:]),
                    method=getattr(cv2, f"CALIB_ROBOT_WORLD_HAND_EYE_{name}"),
                )
            except cv2.error:
                continue
            found[name] = rigid(R, t)
    out = {}
    for name, T in found.items():
        if not np.all(np.isfinite(T)):
            continue
        dt, dr = pose_difference(T, ref) if ref is not None else (float("nan"), float("nan"))
        out[name] = OpenCvEstimate(method=name, T_cam_base=T, translation_diff_m=dt, rotation_diff_deg=dr)
    return out


def opencv_hand_eye(
    mount: CameraMount,
    T_base_gripper: Sequence[npt.ArrayLike] | npt.ArrayLike,
    T_cam_board: Sequence[npt.ArrayLike] | npt.ArrayLike,
    reference_X: npt.ArrayLike,
) -> dict[str, OpenCvEstimate]:
    """OpenCV's estimates for ``mount``, each compared with ``reference_X`` on the mount's own transform ``X``.

    A wrist camera is passed to :func:`opencv_eye_to_hand` as the equivalent fixed camera (FK inverted, see
    :class:`calib.handeye_mount.CameraMount`); its estimate of ``T_cam_tcp`` is inverted to ``T_tcp_cam``
    before the comparison.
    """
    G = as_transforms(T_base_gripper, mount.fk)
    ref = np.asarray(reference_X, dtype=np.float64)
    out = {}
    for name, est in opencv_eye_to_hand(mount.fixed_camera(G), T_cam_board).items():
        dt, dr = pose_difference(mount.fixed_camera(est.T_cam_base), ref)
        out[name] = OpenCvEstimate(method=name, T_cam_base=est.T_cam_base, translation_diff_m=dt, rotation_diff_deg=dr)
    return out
