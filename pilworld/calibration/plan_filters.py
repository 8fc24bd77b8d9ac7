"""The checks a candidate view must pass to be planned, shared by both camera mounts.

A candidate (:class:`pilworld.calibration.plan_sampling.Candidate`) is kept if the whole page projects
inside the image with a margin, every chessboard corner is seen at most ``max_view_angle_deg`` off the
board normal, IK (nearest to the arm's current joints, within the joint limits) reaches the TCP pose, the
base, shoulder and elbow stay near their start, the arm stays above the table, and no line of sight from
the camera to the board passes through an arm (capsule model, :mod:`.occlusion`). Each mount adds what
only it needs (:class:`HeldBoardFilters`: the board above the table and clear of the holding arm;
:class:`CarriedCameraFilters`: the page clear of the camera's own gripper in the image) and orders the
checks; the first that fails names the rejection (docs/calibration.md, "3. Hand-eye" and "Wrist cameras (eye-in-hand)").
"""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import Final

import cv2
import numpy as np
import numpy.typing as npt

from calib.board import ChArUcoBoard
from calib.camera_model import CameraModel
from pilworld.calibration.gripper_mask import MASK_SCALE, gripper_boxes_tcp, gripper_mask
from pilworld.calibration.occlusion import ArmCapsules, arm_capsules, segment_distances
from pilworld.calibration.plan_sampling import Candidate, page_points, unit
from pilworld.calibration.plan_settings import PlannerSettings, WristPlannerSettings
from pilworld.geometry import invert_transform
from pilworld.kinematics.dual_arm import ArmMount, DualArmKinematics
from pilworld.kinematics.fk import fk_frames
from pilworld.kinematics.ik import ik_nearest
from pilworld.types import ARM_LAYOUT, ARM_SIDES

__all__ = ["CarriedCameraFilters", "Filters", "HeldBoardFilters", "arm_mount"]

FloatArray = npt.NDArray[np.float64]
ViewCheck = Callable[[Candidate], bool]
ArmCheck = Callable[[Candidate, FloatArray, ArmCapsules], bool]

_MIN_LINK_Z: Final = 0.04  # m: joint origins stay this far above the table
_MIN_TCP_Z: Final = 0.10  # m: the gripper (and a wrist camera) stay clear of the table and the objects on it
_MIN_BOARD_Z: Final = 0.03  # m: a held plate stays above the table


def arm_mount(kinematics: DualArmKinematics, arm: str) -> ArmMount:
    if arm not in ARM_SIDES:
        raise ValueError(f"arm: expected one of {', '.join(ARM_SIDES)}, got {arm!r}")
    mount: ArmMount = getattr(kinematics, arm)
    return mount


class Filters:
    """The checks of both mounts for ``arm``, with the other arm holding still at ``state`` ``(14,)``."""

    def __init__(
        self,
        settings: PlannerSettings | WristPlannerSettings,
        camera: CameraModel,
        kinematics: DualArmKinematics,
        arm: str,
        state: FloatArray,
    ) -> None:
        self.s = settings
        self.mount = arm_mount(kinematics, arm)
        other = "right" if arm == "left" else "left"
        self.q_start = state[ARM_LAYOUT[arm][0]]
        self.T_base_rig = invert_transform(self.mount.T_rig_base)
        self.others = arm_capsules(getattr(kinematics, other), state[ARM_LAYOUT[other][0]])
        self.width, self.height = camera.width, camera.height
        self.margin_u, self.margin_v = settings.image_margin * camera.width, settings.image_margin * camera.height
        self.cos_view = math.cos(math.radians(settings.max_view_angle_deg))

    def view_checks(self) -> tuple[tuple[str, ViewCheck], ...]:
        """The checks before IK, in order: (rejection reason, check that is True to reject)."""
        return (("not inside the image", self.outside_image), ("too oblique", self.too_oblique))

    def arm_checks(self) -> tuple[tuple[str, ArmCheck], ...]:
        """The checks of the arm at the reached joints, in order."""
        return (("arm too low", self.too_low), ("line of sight blocked by an arm", self.sight_blocked))

    def occluders(self, c: Candidate, own: ArmCapsules) -> ArmCapsules:
        """The capsules a line of sight must clear: this arm's (``own``, at the reached joints) and the other's."""
        return own + self.others

    def outside_image(self, c: Candidate) -> bool:
        proj = c.camera.project_detailed(c.page)
        uv = proj.uv
        inside = (
            proj.in_valid_fov.all()
            and uv[:, 0].min() >= self.margin_u - 0.5
            and uv[:, 0].max() <= self.width - 0.5 - self.margin_u
            and uv[:, 1].min() >= self.margin_v - 0.5
            and uv[:, 1].max() <= self.height - 0.5 - self.margin_v
        )
        return not inside

    def too_oblique(self, c: Candidate) -> bool:
        return bool(np.min(unit(c.eye - c.corners) @ -c.T_rig_board[:3, 2]) < self.cos_view)

    def too_low(self, c: Candidate, q: FloatArray, own: ArmCapsules) -> bool:
        frames = self.mount.T_rig_base @ fk_frames(q, self.mount.dh)
        return bool(frames[1:, 2, 3].min() < _MIN_LINK_Z or c.T_rig_tcp[2, 3] < _MIN_TCP_Z)

    def sight_blocked(self, c: Candidate, q: FloatArray, own: ArmCapsules) -> bool:
        both = self.occluders(c, own)
        lines = np.concatenate([c.corners, c.page])
        dist = segment_distances(np.broadcast_to(c.eye, lines.shape), lines, both.start, both.end)
        return bool(np.any(dist < both.radius + self.s.clearance_m))

    def reach(self, c: Candidate) -> FloatArray | str:
        """The joints that reach ``c`` if it passes every check, else the reason of the first that fails."""
        for reason, rejects in self.view_checks():
            if rejects(c):
                return reason
        q = ik_nearest(self.T_base_rig @ c.T_rig_tcp, self.mount.dh, self.q_start, self.mount.T_flange_tcp)
        if q is None:
            return "unreachable"
        if np.max(np.abs(q[:3] - self.q_start[:3])) > self.s.max_arm_joint_move_rad:
            return "far from the start joints"
        own = arm_capsules(self.mount, q)
        for reason, rejects_arm in self.arm_checks():
            if rejects_arm(c, q, own):
                return reason
        return q


class HeldBoardFilters(Filters):
    """Eye-to-hand: the arm holds the board, so the plate must stay above the table and out of the arm."""

    def __init__(
        self,
        settings: PlannerSettings,
        camera: CameraModel,
        kinematics: DualArmKinematics,
        arm: str,
        state: FloatArray,
        board: ChArUcoBoard,
    ) -> None:
        super().__init__(settings, camera, kinematics, arm, state)
        # The plate must not cut the holding arm's links: a coarse grid over the page (plus the corners).
        self.plate_b = page_points(board, 7, 5)

    def view_checks(self) -> tuple[tuple[str, ViewCheck], ...]:
        return (("below the table", self.board_below_table), *super().view_checks())

    def arm_checks(self) -> tuple[tuple[str, ArmCheck], ...]:
        return (*super().arm_checks(), ("board cuts through the arm", self.plate_cuts_arm))

    def board_below_table(self, c: Candidate) -> bool:
        return bool(c.page[:, 2].min() < _MIN_BOARD_Z)

    def plate_cuts_arm(self, c: Candidate, q: FloatArray, own: ArmCapsules) -> bool:
        links = own.links()
        plate = self.plate_b @ c.T_rig_board[:3, :3].T + c.T_rig_board[:3, 3]
        dist = segment_distances(plate, plate, links.start, links.end)
        return bool(np.any(dist < links.radius + self.s.clearance_m))


class CarriedCameraFilters(Filters):
    """Eye-in-hand: the arm carries the camera, so its own gripper must not cover the page in the image.

    ``max_opening_m`` (the gripper's stroke) and the grip in ``state`` set where the fingers are.
    """

    def __init__(
        self,
        settings: WristPlannerSettings,
        camera: CameraModel,
        kinematics: DualArmKinematics,
        arm: str,
        state: FloatArray,
        board: ChArUcoBoard,
        T_rig_board: FloatArray,
        max_opening_m: float,
    ) -> None:
        super().__init__(settings, camera, kinematics, arm, state)
        blocked = gripper_mask(camera, gripper_boxes_tcp(max_opening_m, float(state[ARM_LAYOUT[arm][1]])))
        self.blocked = cv2.dilate(blocked.astype(np.uint8), np.ones((3, 3), np.uint8)).astype(bool)
        self.page_grid = page_points(board, 15, 11) @ T_rig_board[:3, :3].T + T_rig_board[:3, 3]

    def view_checks(self) -> tuple[tuple[str, ViewCheck], ...]:
        return (*super().view_checks(), ("page behind the gripper in the image", self.behind_gripper))

    def occluders(self, c: Candidate, own: ArmCapsules) -> ArmCapsules:
        # Capsules the camera sits in (the wrist links beside it) are behind it: the gripper mask covers the rest.
        links = own.links()
        near = (
            segment_distances(c.eye[None], c.eye[None], links.start, links.end)[0] < links.radius + self.s.clearance_m
        )
        return self.others + ArmCapsules(
            links.start[~near], links.end[~near], links.radius[~near], links.gripper[~near]
        )

    def behind_gripper(self, c: Candidate) -> bool:
        grid_uv = c.camera.project(self.page_grid)[0]
        iu = np.clip(((grid_uv[:, 0] + 0.5) / MASK_SCALE).astype(int), 0, self.blocked.shape[1] - 1)
        iv = np.clip(((grid_uv[:, 1] + 0.5) / MASK_SCALE).astype(int), 0, self.blocked.shape[0] - 1)
        return bool(self.blocked[iv, iu].any())

    def too_low(self, c: Candidate, q: FloatArray, own: ArmCapsules) -> bool:
        return super().too_low(c, q, own) or bool(c.eye[2] < _MIN_TCP_Z)
