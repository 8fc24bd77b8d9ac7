"""The head camera's hand-eye calibration with one arm or with both: what ``pilworld calibrate handeye`` solves.

One arm: :func:`pilworld.calibration.solve.calibrate_arm`. Both arms (:func:`calibrate_both`): each arm is
solved on its own, the two ``T_cam_base`` are compared (their disagreement is a direct measure of FK,
mount and calibration error), and the combined estimate is a **joint refinement**: one ``T_cam_base`` and
one ``T_tcp_board`` per arm fitted to every corner of both arms' views (the same Huber loss,
:func:`calib.handeye_refine.refine_shared_camera`), started from the arm with the lower residual
(docs/calibration.md, "3. Hand-eye").
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
import numpy.typing as npt

from calib import handeye_refine
from calib.board import ChArUcoBoard
from calib.camera_model import CameraModel
from calib.rotations import pose_difference
from pilworld.calibration.board_views import HandEyeView
from pilworld.calibration.recording import RecordedView
from pilworld.calibration.solve import ArmHandEye, calibrate_arm
from pilworld.kinematics.dual_arm import DualArmKinematics
from pilworld.types import ARM_SIDES

__all__ = ["BothArmsHandEye", "HandEyeOutcome", "calibrate_both", "refine_shared_camera", "solve_recording"]

FloatArray = npt.NDArray[np.float64]


@dataclass(frozen=True, eq=False)
class BothArmsHandEye:
    """Each arm's own result, their disagreement and the joint refinement over both."""

    arms: dict[str, ArmHandEye]
    T_cam_base: FloatArray  #: joint refinement (one camera, one board mount per arm)
    T_tcp_board: dict[str, FloatArray]
    rms_px: float  #: residual RMS of the joint refinement over every corner of both arms
    disagreement_mm: float  #: |t_left - t_right| of the two single-arm T_cam_base
    disagreement_deg: float  #: rotation angle between them
    started_from: str  #: the arm whose single-arm result started the joint refinement

    def to_dict(self) -> dict[str, Any]:
        return {
            "method": "joint refinement of one T_cam_base and one T_tcp_board per arm over both arms' corners "
            f"(Huber), started from the {self.started_from} arm's result",
            "residual_rms_px": self.rms_px,
            "disagreement": {"translation_mm": self.disagreement_mm, "rotation_deg": self.disagreement_deg},
            "T_cam_base": self.T_cam_base.tolist(),
            "T_tcp_board": {arm: T.tolist() for arm, T in self.T_tcp_board.items()},
        }


def calibrate_both(
    views: Sequence[RecordedView],
    camera: CameraModel,
    board: ChArUcoBoard,
    kinematics: DualArmKinematics,
    *,
    huber_px: float = 1.0,
) -> BothArmsHandEye:
    """Calibrate with each arm, compare, then refine one camera over both (see the module docstring)."""
    arms = {arm: calibrate_arm(views, camera, board, kinematics, arm, huber_px=huber_px) for arm in ARM_SIDES}
    dt, dr = pose_difference(arms["left"].T_cam_base, arms["right"].T_cam_base)
    start = min(arms, key=lambda a: arms[a].residual_rms_px)
    X, Ys, rms = refine_shared_camera(
        arms[start].T_cam_base,
        {a: (r.T_tcp_board, list(r.views)) for a, r in arms.items()},
        camera.K,
        camera.dist,
        huber_px=huber_px,
    )
    return BothArmsHandEye(
        arms=arms,
        T_cam_base=X,
        T_tcp_board=Ys,
        rms_px=rms,
        disagreement_mm=dt * 1e3,
        disagreement_deg=dr,
        started_from=start,
    )


def refine_shared_camera(
    T_cam_base: npt.ArrayLike,
    arms: dict[str, tuple[npt.ArrayLike, list[HandEyeView]]],
    K: npt.ArrayLike,
    dist: npt.ArrayLike,
    *,
    huber_px: float = 1.0,
    max_iterations: int = 50,
) -> tuple[FloatArray, dict[str, FloatArray], float]:
    """One ``T_cam_base`` and one ``T_tcp_board`` per arm fitted to all their views' corners.

    :func:`calib.handeye_refine.refine_shared_camera` on each arm's (``T_tcp_board``, views); returns the
    transforms and the plain RMS of the corner errors.
    """
    boards = [
        (
            T_tcp_board,
            np.asarray([d.T_base_gripper for d in views]),
            [d.board_points for d in views],
            [d.image_points for d in views],
        )
        for T_tcp_board, views in arms.values()
    ]
    X, Ys, rms = handeye_refine.refine_shared_camera(
        T_cam_base, boards, K, dist, huber_px=huber_px, max_iterations=max_iterations
    )
    return X, dict(zip(arms, Ys, strict=True)), rms


@dataclass(frozen=True, eq=False)
class HandEyeOutcome:
    """What ``pilworld calibrate handeye`` writes: the estimate for ``arm`` (left, right or both)."""

    arm: str
    camera: CameraModel  #: the intrinsics used, with the estimated T_cam_base
    T_tcp_board: dict[str, FloatArray]  #: estimated board mount per arm
    per_arm: dict[str, ArmHandEye]
    both: BothArmsHandEye | None  #: only for arm == "both"

    @property
    def T_cam_base(self) -> FloatArray:  # noqa: N802 - the name every calibration module uses
        return self.camera.T_cam_base

    @property
    def residual_rms_px(self) -> float:
        return self.both.rms_px if self.both is not None else self.per_arm[self.arm].residual_rms_px

    @property
    def rotation_span_deg(self) -> float:
        """The smallest rotation span of the arms used (each arm must determine the camera on its own)."""
        return min(r.motion.rotation_span_deg for r in self.per_arm.values())

    @property
    def poses(self) -> int:
        return sum(len(r.used) for r in self.per_arm.values())


def solve_recording(
    views: Sequence[RecordedView],
    camera: CameraModel,
    board: ChArUcoBoard,
    kinematics: DualArmKinematics,
    arm: str,
    *,
    huber_px: float = 1.0,
) -> HandEyeOutcome:
    """Calibrate with one arm's views (``arm`` = left or right) or with both (``arm`` = both)."""
    if arm == "both":
        both = calibrate_both(views, camera, board, kinematics, huber_px=huber_px)
        return HandEyeOutcome(arm, camera.with_pose(both.T_cam_base), dict(both.T_tcp_board), both.arms, both)
    if arm not in ARM_SIDES:
        raise ValueError(f"arm: expected left, right or both, got {arm!r}")
    result = calibrate_arm(views, camera, board, kinematics, arm, huber_px=huber_px)
    return HandEyeOutcome(arm, camera.with_pose(result.T_cam_base), {arm: result.T_tcp_board}, {arm: result}, None)
