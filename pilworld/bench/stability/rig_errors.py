"""Probes 4 and 5: the wrong calibrations and robot models given to the models (the simulator keeps the true rig)."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from pilworld.config.rig import RigConfig
    from pilworld.control_video.robot_model import RobotModel

ERROR_SEED = 0  # directions and axes of the camera errors (pilworld.control_video.probes)
CAL_SHIFTS_PX = (0.0, 5.0, 10.0, 20.0)
HEAD_ERRORS = ((0.002, 0.2), (0.005, 0.5), (0.010, 1.0))  # (translation m, rotation deg) of the head camera
WRIST_ERRORS = ((0.002, 0.5), (0.005, 1.0))  # of each wrist camera's mount
ROBOT_ERRORS: tuple[tuple[float, tuple[float, float, float, float] | None], ...] = (
    (0.8, None),
    (1.2, None),
    (1.0, (0.8, 0.3, 0.3, 1.0)),
)  # (radius scale, colour) of the robot model
ERROR_KINDS = ("principal_point", "head_extrinsics", "wrist_mount", "robot_model")
CALIBRATION_KINDS = ERROR_KINDS[:3]  # the JSON's "calibration"; "robot_model" is its "robot_mismatch"


@dataclass(frozen=True)
class RigError:
    """One wrong calibration or robot model given to the models (the simulator keeps the true rig)."""

    kind: str  # "principal_point" | "head_extrinsics" | "wrist_mount" | "robot_model"
    shift_px: float = 0.0  # principal_point
    translation_m: float = 0.0  # head_extrinsics, wrist_mount
    rotation_deg: float = 0.0
    radius_scale: float = 1.0  # robot_model
    rgba: tuple[float, float, float, float] | None = None

    def __post_init__(self) -> None:
        if self.kind not in ERROR_KINDS:
            raise ValueError(f"kind: expected one of {', '.join(ERROR_KINDS)}, got {self.kind!r}")

    @property
    def cameras(self) -> bool:
        return self.kind != "robot_model"

    @property
    def key(self) -> str:
        if self.kind == "principal_point":
            return f"pp{self.shift_px:g}px"
        if self.kind in ("head_extrinsics", "wrist_mount"):
            return f"{self.kind.split('_')[0]}{1000 * self.translation_m:g}mm{self.rotation_deg:g}deg"
        if self.rgba is not None:
            return "rgba" + ",".join(f"{c:g}" for c in self.rgba)
        return f"radius{self.radius_scale:g}"

    @property
    def label(self) -> str:
        if self.kind == "principal_point":
            return f"head principal point +{self.shift_px:g} px"
        if self.kind == "head_extrinsics":
            return f"head camera extrinsics {1000 * self.translation_m:g} mm, {self.rotation_deg:g}°"
        if self.kind == "wrist_mount":
            return f"wrist camera mounts {1000 * self.translation_m:g} mm, {self.rotation_deg:g}°"
        if self.rgba is not None:
            return "robot colour (" + ", ".join(f"{c:g}" for c in self.rgba) + ")"
        return f"robot link radii ×{self.radius_scale:g}"

    @property
    def params(self) -> dict[str, Any]:
        """The error's size for the JSON (with the seed of a camera error's directions)."""
        if self.kind == "principal_point":
            return {"shift_px": self.shift_px}
        if self.kind == "robot_model":
            return {"radius_scale": self.radius_scale, "rgba": None if self.rgba is None else list(self.rgba)}
        return {"translation_m": self.translation_m, "rotation_deg": self.rotation_deg, "seed": ERROR_SEED}

    @property
    def moves_head(self) -> bool:
        """Whether the head camera — so Γ's markers — is wrong: all of it that reaches a model without ``bind_rig``."""
        return self.kind in ("principal_point", "head_extrinsics")

    def rig(self, rig: RigConfig, folder: Path) -> RigConfig:
        """The rig config the models are given (a camera error's calibration files under ``folder/key``)."""
        from pilworld.control_video.probes import perturbed_rig

        if not self.cameras:
            return rig
        head, wrist = self.kind == "head_extrinsics", self.kind == "wrist_mount"
        return perturbed_rig(
            rig,
            folder / self.key,
            principal_shift_px=self.shift_px,
            head_translation_m=self.translation_m if head else 0.0,
            head_rotation_deg=self.rotation_deg if head else 0.0,
            wrist_translation_m=self.translation_m if wrist else 0.0,
            wrist_rotation_deg=self.rotation_deg if wrist else 0.0,
            seed=ERROR_SEED,
        )

    def robot(self, rig: RigConfig) -> RobotModel | None:
        """The robot model the models render (None: the rig's own)."""
        from pilworld.control_video.probes import mismatched_robot

        return None if self.cameras else mismatched_robot(rig, radius_scale=self.radius_scale, rgba=self.rgba)

    def to_json(self) -> dict[str, Any]:
        return {"kind": self.kind, "key": self.key, "label": self.label, "params": self.params}


def rig_errors() -> list[RigError]:
    """Calibration errors (principal point, head extrinsics, wrist mounts), then robot-model errors."""
    return [
        *(RigError("principal_point", shift_px=s) for s in CAL_SHIFTS_PX if s),
        *(RigError("head_extrinsics", translation_m=t, rotation_deg=a) for t, a in HEAD_ERRORS),
        *(RigError("wrist_mount", translation_m=t, rotation_deg=a) for t, a in WRIST_ERRORS),
        *(RigError("robot_model", radius_scale=s, rgba=c) for s, c in ROBOT_ERRORS),
    ]
