"""The robot alone, as the simulated rig is built: geoms, their parts, and where they are for a 14-d vector.

One geometry for everything: the robot model is the MuJoCo model the simulated rig is generated from
(:func:`simrig.scene.build_mjcf`: the arms from the rig's UR models, mounts, grippers; the table,
floor and objects hidden) — or the user's own MJCF robot (``robot_model:`` in the rig config). Joint
positions and finger openings are set directly (no physics) and MuJoCo's forward kinematics places the
geoms. Both renderers (:mod:`~pilworld.control_video.rasterise`, the analytic one, and
:mod:`~pilworld.control_video.robot_render_mujoco`) read their geometry from here.

Part ids (uint8): 0 background, 1 left arm, 2 left fingers, 3 right arm, 4 right fingers.
"""

from __future__ import annotations

import copy
from collections.abc import Mapping
from dataclasses import dataclass
from functools import cached_property
from typing import Any, Final

import numpy as np
from numpy.typing import NDArray

from pilworld.config.rig import RigConfig
from pilworld.geometry import as_finite_array
from pilworld.types import ARM_LAYOUT, ARM_SIDES, STATE_DIM
from simrig.gl import mujoco
from simrig.scene import build_mjcf, compile_scene

PART_NAMES: Final = ("background", "left_arm", "left_fingers", "right_arm", "right_fingers")
PART_IDS: Final = {name: i for i, name in enumerate(PART_NAMES)}
#: MuJoCo geom group that hides what is not the robot (table, floor, objects) from MuJoCo renders.
HIDDEN_GROUP: Final = 5
#: Geom types the analytic rasteriser draws (MuJoCo's mjtGeom numbering).
SPHERE, CAPSULE, ELLIPSOID, CYLINDER, BOX, MESH = 2, 3, 4, 5, 6, 7
GEOM_TYPE_NAMES: Final = {
    0: "plane",
    1: "hfield",
    2: "sphere",
    3: "capsule",
    4: "ellipsoid",
    5: "cylinder",
    6: "box",
    7: "mesh",
    8: "sdf",
}


def part_id(side: str, fingers: bool) -> int:
    return PART_IDS[f"{side}_{'fingers' if fingers else 'arm'}"]


def _designed_head(rig: RigConfig) -> RigConfig:
    """The rig with a plain pinhole head camera: the robot model needs no camera, and MuJoCo cannot
    place a distorted one (a calibrated real camera), so the generated MJCF gets a stand-in."""
    data = rig.model_dump()
    stand_in = {"eye": [0.0, 0.0, 2.0], "target": [0.0, 0.0, 0.0], "up": [1, 0, 0], "fovy_deg": 45}
    data["head_camera"] = {"look_at": stand_in}
    for cam in data.get("wrist_cameras", {}).values():
        cam["file"] = None
    data["hardware"] = None
    return RigConfig.model_validate(data)


@dataclass(frozen=True, eq=False)
class RobotModel:
    """The robot's MuJoCo model, which of its geoms are robot (and which part), and the 14-d → qpos map."""

    model: Any  # mujoco.MjModel (robot geoms visible, everything else in HIDDEN_GROUP)
    geom_ids: NDArray[np.int64]  # (G,) robot geoms, in model order
    geom_part: NDArray[np.uint8]  # (G,) part id of each
    arm_qadr: dict[str, NDArray[np.int64]]  # side → qpos addresses of its six arm joints
    finger_qadr: dict[str, NDArray[np.int64]]  # side → qpos addresses of its finger joints
    finger_range: dict[str, NDArray[np.float64]]  # side → (n, 2) qpos at grip 0 and at grip 1
    source: str  # "generated from rig <name>" or the MJCF path

    @classmethod
    def from_rig(cls, rig: RigConfig) -> RobotModel:
        """The generated robot of ``rig`` (as the simulator builds it), or ``rig.robot_model``'s MJCF."""
        if rig.robot_model is not None:
            cfg = rig.robot_model
            arms = {str(k): v for k, v in cfg.arm_joints.items()}
            fingers = {str(k): v for k, v in cfg.finger_joints.items()}
            return cls.from_mjcf(cfg.mjcf, arms, fingers)
        model = compile_scene(build_mjcf(_designed_head(rig)), f"robot model of rig {rig.name!r}")
        arm_joints = {side: [f"{side}_joint_{i + 1}" for i in range(6)] for side in ARM_SIDES}
        finger_joints = {side: [f"{side}_finger_a", f"{side}_finger_b"] for side in ARM_SIDES}
        return cls._build(model, arm_joints, finger_joints, f"generated from rig {rig.name!r}")

    @classmethod
    def from_mjcf(
        cls, path: str, arm_joints: Mapping[str, list[str]], finger_joints: Mapping[str, list[str]] | None = None
    ) -> RobotModel:
        """A user's MJCF robot; ``arm_joints``/``finger_joints`` map the 14-d vector onto its joints."""
        try:
            model = mujoco.MjModel.from_xml_path(str(path))
        except ValueError as exc:
            raise ValueError(f"robot_model.mjcf {path}: does not compile: {exc}") from exc
        return cls._build(model, arm_joints, finger_joints or {}, str(path))

    @classmethod
    def _build(
        cls, model: Any, arm_joints: Mapping[str, list[str]], finger_joints: Mapping[str, list[str]], source: str
    ) -> RobotModel:
        def joint(name: str, what: str) -> Any:
            try:
                return model.joint(name)
            except KeyError:
                names = [model.joint(j).name for j in range(model.njnt)]
                raise ValueError(f"{what}: joint {name!r} not in the robot model {source} (joints: {names})") from None

        # Each body's parent chain decides its part: below a finger joint's body → fingers, below the
        # arm's root (the parent of its first joint's body) → arm.
        parent = model.body_parentid
        part_of_body = np.zeros(model.nbody, dtype=np.uint8)
        arm_qadr, finger_qadr, finger_range = {}, {}, {}
        for side in ARM_SIDES:
            js = [joint(n, f"arm_joints.{side}") for n in arm_joints.get(side, [])]
            if len(js) != 6:
                raise ValueError(f"arm_joints.{side}: expected six joints, got {len(js)}")
            arm_qadr[side] = np.array([int(j.qposadr[0]) for j in js], dtype=np.int64)
            root = int(parent[int(js[0].bodyid[0])])
            fjs = [joint(n, f"finger_joints.{side}") for n in finger_joints.get(side, [])]
            finger_qadr[side] = np.array([int(j.qposadr[0]) for j in fjs], dtype=np.int64)
            finger_range[side] = np.array([[float(j.range[0]), float(j.range[1])] for j in fjs]).reshape(-1, 2)
            finger_bodies = {int(j.bodyid[0]) for j in fjs}
            for b in range(1, model.nbody):
                chain = [b]
                while chain[-1] != 0:
                    chain.append(int(parent[chain[-1]]))
                if any(c in finger_bodies for c in chain):
                    part_of_body[b] = part_id(side, fingers=True)
                elif root in chain and part_of_body[b] == 0:
                    part_of_body[b] = part_id(side, fingers=False)
        geom_part = part_of_body[model.geom_bodyid]
        # A world-body geom of a user model (root 0 for an arm mounted on the world) is not the robot.
        geom_part[model.geom_bodyid == 0] = 0
        robot = np.flatnonzero(geom_part > 0)
        if robot.size == 0:
            raise ValueError(f"robot model {source}: no geoms below the arm joints")
        hidden = np.setdiff1d(np.arange(model.ngeom), robot)
        model.geom_group[hidden] = HIDDEN_GROUP
        return cls(
            model=model,
            geom_ids=robot.astype(np.int64),
            geom_part=geom_part[robot].astype(np.uint8),
            arm_qadr=arm_qadr,
            finger_qadr=finger_qadr,
            finger_range=finger_range,
            source=source,
        )

    @cached_property
    def _data(self) -> Any:
        return mujoco.MjData(self.model)

    @property
    def geom_type(self) -> NDArray[np.int64]:
        return np.asarray(self.model.geom_type[self.geom_ids], dtype=np.int64)

    @property
    def geom_size(self) -> NDArray[np.float64]:
        return np.asarray(self.model.geom_size[self.geom_ids], dtype=np.float64)

    @property
    def geom_rgba(self) -> NDArray[np.float64]:
        return np.asarray(self.model.geom_rgba[self.geom_ids], dtype=np.float64)

    def qpos(self, q14: NDArray[np.floating]) -> NDArray[np.float64]:
        """(..., 14) → (..., nq): arm joints as given, each finger joint at ``lo + grip · (hi − lo)``.

        Grips are clipped to [0, 1] (a gripper cannot open past its stroke).
        """
        q = as_finite_array(q14, "q14", (STATE_DIM,))
        out = np.broadcast_to(np.asarray(self.model.qpos0, dtype=np.float64), (*q.shape[:-1], self.model.nq)).copy()
        for side, (arm, grip) in ARM_LAYOUT.items():
            out[..., self.arm_qadr[side]] = q[..., arm]
            g = np.clip(q[..., grip], 0.0, 1.0)[..., None]
            lo, hi = self.finger_range[side][:, 0], self.finger_range[side][:, 1]
            out[..., self.finger_qadr[side]] = lo + g * (hi - lo)
        return out

    def geom_poses(self, q14: NDArray[np.floating]) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """Rig-frame positions (N, G, 3) and rotations (N, G, 3, 3) of the robot geoms for (N, 14) vectors."""
        qpos = self.qpos(np.asarray(q14, dtype=np.float64).reshape(-1, STATE_DIM))
        n, ids = qpos.shape[0], self.geom_ids
        pos = np.empty((n, ids.size, 3))
        rot = np.empty((n, ids.size, 3, 3))
        m, d = self.model, self._data
        for i in range(n):
            d.qpos[:] = qpos[i]
            mujoco.mj_kinematics(m, d)
            pos[i] = d.geom_xpos[ids]
            rot[i] = d.geom_xmat[ids].reshape(-1, 3, 3)
        return pos, rot

    def scaled(self, radius_scale: float = 1.0, rgba: tuple[float, float, float, float] | None = None) -> RobotModel:
        """A mismatched copy for the stability probes: round geoms' radii × ``radius_scale``, colours replaced."""
        if not 0.1 <= radius_scale <= 10.0:
            raise ValueError(f"radius_scale: expected a factor in [0.1, 10], got {radius_scale!r}")
        model = copy.deepcopy(self.model)
        round_geoms = self.geom_ids[np.isin(self.geom_type, (SPHERE, CAPSULE, CYLINDER))]
        model.geom_size[round_geoms, 0] *= radius_scale
        if rgba is not None:
            model.geom_rgba[self.geom_ids] = np.asarray(rgba, dtype=np.float64)
        return RobotModel(
            model, self.geom_ids, self.geom_part, self.arm_qadr, self.finger_qadr, self.finger_range, self.source
        )
