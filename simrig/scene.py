"""The simulated rig's MuJoCo scene, generated from the rig config (MJCF text, primitives only).

Geometry comes from the same sources as everything else, so the simulator, the control video and the
calibration check agree by construction:

* each arm is a chain of bodies whose frames *are* the DH frames of ``pilworld.kinematics`` — body
  ``link{i+1}`` sits at ``(a_i, 0, d_i)`` in ``link{i}`` rotated by ``Rx(alpha_i)`` and hinges about its
  own z, exactly ``T_i = Rz(q_i) Tz(d_i) Tx(a_i) Rx(alpha_i)`` — followed by the flange and a ``tcp``
  site at the rig's ``T_flange_tcp``;
* ``cam_high`` is placed and sized from ``RigConfig.head_camera_model`` (the rig's ``CameraModel``);
* wrist cameras sit at their configured pose in the TCP frame.

Arm links carry gravity compensation and position actuators (the UR controller's job), and do not
collide (a scripted or learned policy is not asked to avoid its own forearm); palm and fingers collide
with the table and the objects.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from pilworld.config.rig import ArmConfig, RigConfig
from pilworld.geometry import invert_transform
from pilworld.kinematics.ur_dh import dh_params
from pilworld.types import ARM_SIDES
from simrig import appearance as app
from simrig.board_mount import BoardMount
from simrig.gl import mujoco  # imported through gl: the GL backend is chosen before MuJoCo loads
from simrig.hand_board import HandBoard
from simrig.objects import Assets, FixtureSpec, GeomSpec, ObjectSpec
from simrig.table_board import TableBoard

ARM_RGBA = (0.62, 0.63, 0.66, 1.0)
JOINT_RGBA = (0.28, 0.30, 0.33, 1.0)
GRIPPER_RGBA = (0.18, 0.18, 0.2, 1.0)
TABLE_RGBA = (0.75, 0.72, 0.65, 1.0)
FLOOR_RGBA = (0.35, 0.35, 0.37, 1.0)
TABLE_HALF = (0.55, 0.6, 0.02)  # x, y, thickness half-sizes [m]
TABLE_CENTRE_X = -0.05
FINGER_HALF = (0.011, 0.005, 0.03)  # tangential, closing-direction thickness, length half-sizes [m]
FINGER_CENTRE_BELOW_TCP = -0.012  # finger pad centre along the tool z relative to the TCP
PALM_HALF = (0.03, 0.055, 0.02)
# "Closed" commands each finger this far past contact, so a grasp presses with ≈ kp·squeeze (capped by
# the force limit) whatever the object's width, as a real gripper's force setting does; a thin bowl
# wall would otherwise be held with almost no force.
FINGER_SQUEEZE = 0.025


@dataclass(frozen=True)
class SceneSettings:
    """Physics settings derived from the rig's rates (one control step = ``substeps`` physics steps)."""

    control_rate_hz: float
    substeps: int
    arm_kp: float = 4000.0  # N·m/rad: stiff position servo, critically damped (dampratio 1)
    arm_armature: float = 0.3  # kg·m² reflected rotor inertia; keeps the stiff servo stable at this step
    finger_kp: float = 800.0  # N/m
    finger_force: float = 25.0  # N, the gripper's force limit per finger
    # Shadow maps cost 3–6× the rest of a 128² render on Mesa's CPU rasteriser (4 ms → 14–25 ms per
    # view, measured); the key light's shading already separates faces, so they are off by default
    # (the ``varied`` appearance turns them on, at a smaller shadow map: simrig.appearance.SHADOW_SIZE).
    shadows: bool = False

    @property
    def timestep(self) -> float:
        return 1.0 / (self.control_rate_hz * self.substeps)


def settings_for(rig: RigConfig) -> SceneSettings:
    """Physics sub-steps close to the servo rate (500 Hz for a UR) but an integer per control step."""
    substeps = max(1, round(rig.servo_rate_hz / rig.control_rate_hz))
    return SceneSettings(control_rate_hz=rig.control_rate_hz, substeps=substeps)


def _f(values: Iterable[float]) -> str:
    return " ".join(f"{float(v):.10g}" for v in values)


def _mat_to_quat(R: NDArray[np.float64]) -> tuple[float, float, float, float]:
    """Rotation matrix → unit quaternion (w, x, y, z), MuJoCo's order."""
    q = np.zeros(4)
    mujoco.mju_mat2Quat(q, np.ascontiguousarray(R, dtype=np.float64).reshape(9))
    return (float(q[0]), float(q[1]), float(q[2]), float(q[3]))


def _geom_xml(g: GeomSpec, name: str | None = None, extra: str = "") -> str:
    attrs = [f'type="{g.type}"', f'rgba="{_f(g.rgba)}"', f'pos="{_f(g.pos)}"', f'quat="{_f(g.quat)}"']
    if g.size:
        attrs.insert(1, f'size="{_f(g.size)}"')
    if g.mesh is not None:
        attrs.append(f'mesh="{g.mesh}"')
    if g.material is not None:
        attrs.append(f'material="{g.material}"')
    if name:
        attrs.insert(0, f'name="{name}"')
    if not g.collide:
        attrs.append('contype="0" conaffinity="0"')
    return f"<geom {' '.join(attrs)} {extra}/>"


# OpenCV camera axes (x right, y down, z forward) → MuJoCo camera axes (x right, y up, looking along −z).
_CV_TO_MJ = np.diag([1.0, -1.0, -1.0])


def _camera_xml(name: str, T_parent_cam_cv: NDArray[np.float64], fovy_deg: float) -> str:
    quat = _mat_to_quat(T_parent_cam_cv[:3, :3] @ _CV_TO_MJ)
    return f'<camera name="{name}" pos="{_f(T_parent_cam_cv[:3, 3])}" quat="{_f(quat)}" fovy="{fovy_deg:.10g}"/>'


def _arm_xml(
    side: str, arm: ArmConfig, rig: RigConfig, s: SceneSettings, board_mount: BoardMount | None = None
) -> tuple[str, list[str]]:
    """The arm's body tree and its actuator lines."""
    dh = dh_params(arm.model)
    T_base = arm.base_pose.matrix()
    base_quat = _mat_to_quat(T_base[:3, :3])
    lines = [f'<body name="{side}_base" pos="{_f(T_base[:3, 3])}" quat="{_f(base_quat)}">']
    lines.append(f'<geom type="cylinder" size="0.075 0.02" pos="0 0 0.02" rgba="{_f(JOINT_RGBA)}" class="visual"/>')
    actuators: list[str] = []
    lower, upper = dh.lower_limits, dh.upper_limits
    for i in range(6):
        joint = f"{side}_joint_{i + 1}"
        if i == 0:
            pos, quat = (0.0, 0.0, 0.0), (1.0, 0.0, 0.0, 0.0)
        else:
            a, d, alpha = dh.a[i - 1], dh.d[i - 1], dh.alpha[i - 1]
            pos = (a, 0.0, d)
            quat = (math.cos(alpha / 2), math.sin(alpha / 2), 0.0, 0.0)
        lines.append(f'<body name="{side}_link{i + 1}" pos="{_f(pos)}" quat="{_f(quat)}" gravcomp="1">')
        lines.append(
            f'<joint name="{joint}" axis="0 0 1" range="{lower[i]:.10g} {upper[i]:.10g}" armature="{s.arm_armature}"'
            ' damping="2"/>'
        )
        # Visuals: a housing around the joint axis and a capsule along the DH offset to the next frame.
        radius = 0.06 if i < 3 else 0.045
        lines.append(
            f'<geom type="cylinder" size="{radius * 0.8:.4g} {radius:.4g}" rgba="{_f(JOINT_RGBA)}" class="visual"'
            ' mass="1.5"/>'
        )
        a, d = dh.a[i], dh.d[i]
        if math.hypot(a, d) > 1e-6:
            lines.append(
                f'<geom type="capsule" fromto="0 0 0 {a:.10g} 0 {d:.10g}" size="{radius * 0.75:.4g}" '
                f'rgba="{_f(ARM_RGBA)}" class="visual" mass="2"/>'
            )
        actuators.append(
            f'<position name="{joint}" joint="{joint}" kp="{s.arm_kp}" dampratio="1" '
            f'ctrlrange="{lower[i]:.10g} {upper[i]:.10g}" forcerange="-400 400"/>'
        )
    # Flange: the last DH transform Tz(d6)·Tx(a6)·Rx(alpha6) from link 6.
    a6, d6, alpha6 = dh.a[5], dh.d[5], dh.alpha[5]
    lines.append(
        f'<body name="{side}_flange" pos="{_f((a6, 0.0, d6))}" '
        f'quat="{_f((math.cos(alpha6 / 2), math.sin(alpha6 / 2), 0.0, 0.0))}" gravcomp="1">'
    )
    lines += _gripper_xml(side, arm, rig, s, actuators, board_mount)
    lines.append("</body>")  # flange
    lines += ["</body>"] * 6
    lines.append("</body>")  # base
    return "\n".join(lines), actuators


def _gripper_xml(
    side: str,
    arm: ArmConfig,
    rig: RigConfig,
    s: SceneSettings,
    actuators: list[str],
    board_mount: BoardMount | None = None,
) -> list[str]:
    """Palm, two slide fingers closing along the tool y axis, the TCP site, the wrist camera (and a board)."""
    T_tcp = arm.tcp.matrix()
    tcp_quat = _mat_to_quat(T_tcp[:3, :3])
    lines = [f'<body name="{side}_tcp_frame" pos="{_f(T_tcp[:3, 3])}" quat="{_f(tcp_quat)}" gravcomp="1">']
    lines.append(f'<site name="{side}_tcp" size="0.004" rgba="1 0 0 0" group="5"/>')
    tcp_z = float(T_tcp[2, 3])
    # Palm and coupling, from the flange (at −tcp_z along the tool axis) to just above the fingers.
    palm_z = -(FINGER_HALF[2] * 2 + PALM_HALF[2]) + FINGER_CENTRE_BELOW_TCP + FINGER_HALF[2]
    lines.append(
        f'<geom name="{side}_coupling" type="cylinder" size="0.035 {(tcp_z + palm_z) / 2:.6g}" '
        f'pos="0 0 {(-tcp_z + palm_z) / 2:.6g}" rgba="{_f(GRIPPER_RGBA)}" class="visual" mass="0.3"/>'
    )
    lines.append(
        f'<geom name="{side}_palm" type="box" size="{_f(PALM_HALF)}" pos="0 0 {palm_z:.6g}" '
        f'rgba="{_f(GRIPPER_RGBA)}" mass="0.4"/>'
    )
    half_open = arm.gripper.max_opening_m / 2
    for finger, sign in (("a", 1.0), ("b", -1.0)):
        joint = f"{side}_finger_{finger}"
        lines.append(f'<body name="{joint}" pos="0 0 {FINGER_CENTRE_BELOW_TCP}" gravcomp="1">')
        lines.append(
            f'<joint name="{joint}" type="slide" axis="0 {sign:.0f} 0" range="0 {half_open:.6g}" damping="5" '
            'armature="0.05" solreflimit="0.002 1" solimplimit="0.99 0.999 0.001"/>'
        )
        lines.append(
            f'<geom name="{joint}_pad" type="box" size="{_f(FINGER_HALF)}" pos="0 {sign * FINGER_HALF[1]:.6g} 0" '
            f'rgba="{_f(GRIPPER_RGBA)}" mass="0.05" friction="1.5 0.02 0.001" condim="4" priority="1"/>'
        )
        lines.append("</body>")
        actuators.append(
            f'<position name="{joint}" joint="{joint}" kp="{s.finger_kp}" dampratio="1" '
            f'ctrlrange="{-FINGER_SQUEEZE:.6g} {half_open:.6g}" forcerange="-{s.finger_force} {s.finger_force}"/>'
        )
    for cam_name, cam in rig.wrist_cameras.items():
        if cam.arm == side:
            lines.append(_camera_xml(cam_name, cam.pose_in_tcp.matrix(), cam.fovy_deg))
    if board_mount is not None and board_mount.arm == side:
        lines.append(board_mount.geom_xml())
    lines.append("</body>")
    return lines


def _head_camera_xml(rig: RigConfig) -> str:
    cam = rig.head_camera_model
    if cam.dist.size and np.any(cam.dist != 0):
        raise ValueError(
            f"head camera of rig {rig.name!r}: MuJoCo renders undistorted pinhole cameras only; the simulated rig "
            "needs a distortion-free head camera (use head_camera.look_at)"
        )
    fx, fy, cx, cy = cam.K[0, 0], cam.K[1, 1], cam.K[0, 2], cam.K[1, 2]
    w, h = cam.width, cam.height
    if abs(fx - fy) > 1e-6 * fx or abs(cx - (w - 1) / 2) > 1e-6 or abs(cy - (h - 1) / 2) > 1e-6:
        raise ValueError(
            f"head camera of rig {rig.name!r}: the simulator needs square pixels and a centred principal point "
            f"(got fx={fx:.3f}, fy={fy:.3f}, cx={cx:.3f}, cy={cy:.3f} for {w}x{h})"
        )
    fovy = math.degrees(2.0 * math.atan(h / (2.0 * fy)))
    return _camera_xml("cam_high", invert_transform(cam.T_cam_base), fovy)


def _object_xml(obj: ObjectSpec) -> str:
    lines = [f'<body name="{obj.name}" pos="0 0 -1">', f'<freejoint name="{obj.name}_free"/>']
    volumes = [_volume(g) for g in obj.geoms]
    total = sum(volumes)
    for k, (g, vol) in enumerate(zip(obj.geoms, volumes, strict=True)):
        mass = obj.mass * vol / total
        friction = f'friction="{obj.friction} 0.01 0.0005"'
        lines.append(_geom_xml(g, name=f"{obj.name}_g{k}", extra=f'mass="{mass:.6g}" {friction} condim="4"'))
    lines.append("</body>")
    return "\n".join(lines)


def _volume(g: GeomSpec) -> float:
    if g.volume is not None:
        return g.volume
    s = g.size
    if g.type == "box":
        return 8 * s[0] * s[1] * s[2]
    if g.type == "cylinder":
        return math.pi * s[0] ** 2 * 2 * s[1]
    if g.type == "sphere":
        return 4 / 3 * math.pi * s[0] ** 3
    if g.type == "capsule":
        return math.pi * s[0] ** 2 * (2 * s[1] + 4 / 3 * s[0])
    raise ValueError(f"unsupported geom type {g.type!r} (box, cylinder, sphere, capsule; mesh with its volume)")


def _fixture_xml(fx: FixtureSpec) -> str:
    lines = [f'<body name="{fx.name}" pos="{_f(fx.pos)}" quat="{_f(fx.quat)}">']
    lines += [_geom_xml(g, name=f"{fx.name}_g{k}") for k, g in enumerate(fx.geoms)]
    lines.append("</body>")
    return "\n".join(lines)


def build_mjcf(
    rig: RigConfig,
    objects: Sequence[ObjectSpec] = (),
    fixtures: Sequence[FixtureSpec] = (),
    markers: Sequence[tuple[str, tuple[float, float, float], float]] = (),
    board_mount: BoardMount | None = None,
    table_board: TableBoard | None = None,
    hand_board: HandBoard | None = None,
    *,
    appearance: str = app.DEFAULT_APPEARANCE,
) -> str:
    """The MJCF of the rig with a task's objects and fixtures; ``markers`` are (name, xyz, radius) spheres.

    ``board_mount`` adds a calibration board on one gripper; its texture must then be passed to
    :func:`compile_scene` as ``assets=board_mount.assets()``. ``table_board`` adds one lying on the table
    (``assets=table_board.assets()``), for the wrist cameras. ``hand_board`` adds one a person holds up
    (a mocap body, ``assets=hand_board.assets()``), for intrinsics.

    ``appearance`` (:mod:`simrig.appearance`): ``"flat"`` is the plain look; ``"varied"`` textures the
    table and every untextured object and turns shadow maps on; its textures must be passed to
    :func:`compile_scene` too (``appearance_assets``).
    """
    varied = app.check_appearance(appearance) == "varied"
    s = settings_for(rig)
    look_assets = Assets()
    if varied:
        objects, fixtures, look_assets = app.textured_scene(objects, fixtures)
    w, h = rig.image_size.width, rig.image_size.height
    arms = [_arm_xml(side, getattr(rig.arms, side), rig, s, board_mount) for side in ARM_SIDES]
    asset_xml = "" if board_mount is None else f"\n  <asset>{board_mount.asset_xml()}</asset>"
    if table_board is not None:
        asset_xml += f"\n  <asset>{table_board.asset_xml()}</asset>"
    if hand_board is not None:
        asset_xml += f"\n  <asset>{hand_board.asset_xml()}</asset>"
    task_assets = scene_assets(objects, fixtures)
    if task_assets.xml:
        asset_xml += "\n  <asset>" + "".join(task_assets.xml) + "</asset>"
    table_look = f'rgba="{_f(TABLE_RGBA)}"'
    shadows, quality = s.shadows, 'shadowsize="1024"'
    if varied:
        asset_xml += "\n  <asset>" + "".join(look_assets.xml) + "</asset>"
        table_look = f'rgba="1 1 1 1" material="{app.table_material_name(0)}"'
        shadows = True
        quality = (
            f'shadowsize="{app.SHADOW_SIZE}" numslices="{app.NUM_SLICES}" numstacks="{app.NUM_STACKS}" '
            f'offsamples="{app.OFF_SAMPLES}"'
        )
    tx = TABLE_CENTRE_X
    marker_xml = [
        f'<site name="{name}" type="sphere" pos="{_f(xyz)}" size="{r:.6g}" rgba="1 0 1 1"/>' for name, xyz, r in markers
    ]
    return f"""<mujoco model="pilworld_{rig.name}">
  <compiler angle="radian" autolimits="true" inertiafromgeom="true"/>
  <option timestep="{s.timestep:.10g}" integrator="implicitfast" cone="elliptic" impratio="5"/>
  <size memory="32M"/>
  <visual>
    <global offwidth="{max(w, 640)}" offheight="{max(h, 480)}"/>
    <quality {quality}/>
    <headlight ambient="0.35 0.35 0.35" diffuse="0.35 0.35 0.35" specular="0.05 0.05 0.05"/>
  </visual>{asset_xml}
  <default>
    <default class="visual"><geom contype="0" conaffinity="0"/></default>
    <geom solref="0.004 1" solimp="0.95 0.99 0.001"/>
  </default>
  <worldbody>
    <light name="key" pos="0.3 -0.4 1.6" dir="-0.2 0.25 -1" diffuse="0.55 0.55 0.55" specular="0.1 0.1 0.1"
      castshadow="{str(shadows).lower()}"/>
    <geom name="floor" type="plane" pos="0 0 -0.75" size="3 3 0.05" rgba="{_f(FLOOR_RGBA)}" contype="0"
      conaffinity="0"/>
    <geom name="table" type="box" pos="{tx} 0 {-TABLE_HALF[2]}" size="{_f(TABLE_HALF)}" {table_look}
      friction="0.8 0.01 0.0005"/>
    {_head_camera_xml(rig)}
    {"" if table_board is None else table_board.geom_xml()}
    {"" if hand_board is None else hand_board.body_xml()}
    {"".join(marker_xml)}
    {arms[0][0]}
    {arms[1][0]}
    {"".join(_fixture_xml(fx) for fx in fixtures)}
    {"".join(_object_xml(o) for o in objects)}
  </worldbody>
  <contact>
    <exclude body1="left_link6" body2="left_flange"/>
    <exclude body1="right_link6" body2="right_flange"/>
  </contact>
  <actuator>
    {"".join(arms[0][1])}
    {"".join(arms[1][1])}
  </actuator>
</mujoco>
"""


def scene_assets(objects: Sequence[ObjectSpec] = (), fixtures: Sequence[FixtureSpec] = ()) -> Assets:
    """The textures, materials and meshes a task's objects and fixtures need (pass ``.files`` to compile)."""
    out = Assets()
    items: list[ObjectSpec | FixtureSpec] = [*objects, *fixtures]
    for item in items:
        out = out + item.assets
    return out


def appearance_assets(
    objects: Sequence[ObjectSpec] = (), fixtures: Sequence[FixtureSpec] = (), appearance: str = app.DEFAULT_APPEARANCE
) -> Assets:
    """The textures :func:`build_mjcf` adds for ``appearance`` (none for ``flat``; pass ``.files`` to compile)."""
    if app.check_appearance(appearance) == "flat":
        return Assets()
    return app.textured_scene(objects, fixtures)[2]


def compile_scene(xml: str, what: str = "simulated rig scene", assets: Mapping[str, bytes] | None = None) -> Any:
    """Compile MJCF text into an ``MjModel``; a compile error names ``what`` was being built.

    ``assets`` maps file names used in the MJCF (e.g. a board texture) to their bytes.
    """
    try:
        if assets:
            return mujoco.MjModel.from_xml_string(xml, assets=dict(assets))
        return mujoco.MjModel.from_xml_string(xml)
    except ValueError as exc:
        raise ValueError(f"{what} does not compile: {exc}") from exc
