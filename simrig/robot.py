"""``SimRobot``: the simulated dual-arm rig behind the ``Robot`` contract, plus sim-only extras.

One ``send_action`` is one control step (30 Hz by default). Underneath, the command is interpolated
linearly over the physics sub-steps (≈500 Hz, as a UR controller's servoJ interpolates) and tracked by
stiff position servos; arm joints are rate-limited to the UR's 180 °/s and grips to a full stroke in
0.5 s, and the command actually applied is returned. ``observe`` renders every camera headless; under
``appearance="varied"`` (:mod:`simrig.appearance`) the scene is textured, lit differently per episode and
every image goes through a camera model (exposure, white balance, noise, JPEG), all seeded by the reset.

Sim-only extras: :meth:`SimRobot.reset` builds a subtask start (earlier subtasks already done, with
``H_h`` history frames at stride Δ before it), :meth:`SimRobot.object_poses` and
:meth:`SimRobot.check_subtask` expose privileged task state to judges — never to policies. For hand-eye
calibration a ChArUco board can be mounted on one gripper (``board_mount``) and any camera rendered at
another resolution with the same field of view (``render(camera, width, height)``).
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from types import TracebackType
from typing import Any

import numpy as np
import numpy.typing as npt
from numpy.typing import NDArray

from hw_drivers.robot import DeviceNotConnectedError
from hw_drivers.safety import dual_arm_speed_caps
from pilworld.config.rig import RigConfig
from pilworld.geometry import is_rigid_transform
from pilworld.types import ARM_LAYOUT, ARM_SIDES, LEFT_ARM, RIGHT_ARM, STATE_DIM, Observation, RobotSpec, Start, Subtask
from simrig.appearance import DEFAULT_APPEARANCE, Look, apply_look, camera_effects, check_appearance, draw_look
from simrig.board_mount import BoardMount
from simrig.files import SIM_RIG
from simrig.gl import make_renderer, mujoco
from simrig.hand_board import PARKED, HandBoard
from simrig.poses import HOME_Q14
from simrig.scene import FINGER_SQUEEZE, appearance_assets, build_mjcf, compile_scene, scene_assets, settings_for
from simrig.table_board import TableBoard
from simrig.tasks import Layout, ObjectPose, Task, make_task

SETTLE_S = 0.5  # physics time given to a new layout before the lead-in


@dataclass(frozen=True)
class SubtaskCheck:
    """The privileged verdict on one subtask: placed, released, and still placed after settling."""

    success: bool
    in_place: bool
    released: bool
    stable: bool
    reason: str


def _check_int(name: str, value: object, *, minimum: int) -> None:
    if isinstance(value, bool) or not isinstance(value, int) or value < minimum:
        raise ValueError(f"{name}: expected an integer >= {minimum}, got {value!r}")


class SimRobot:
    """The MuJoCo dual-arm rig with one task's objects; implements ``hw_drivers.robot.Robot``."""

    def __init__(
        self,
        rig: RigConfig | str | Path = SIM_RIG,
        task: str | Path | Task = "sort_cubes",
        *,
        board_mount: BoardMount | None = None,
        table_board: TableBoard | None = None,
        hand_board: HandBoard | None = None,
        appearance: str = DEFAULT_APPEARANCE,
    ) -> None:
        # "flat" or "varied" (simrig.appearance): textures, per-episode lighting and camera effects.
        self.appearance = check_appearance(appearance)
        self.rig = rig if isinstance(rig, RigConfig) else RigConfig.load(rig)
        self.task = task if isinstance(task, Task) else make_task(task)
        self.board_mount = board_mount  # a calibration board on one gripper (visual only), or None
        self.table_board = table_board  # a calibration board lying on the table (visual only), or None
        self.hand_board = hand_board  # a calibration board a person holds up (mocap, visual only), or None
        base = self.rig.robot_spec()
        speeds = dual_arm_speed_caps()
        self._spec = RobotSpec(
            joint_names=base.joint_names,
            lower=base.lower,
            upper=base.upper,
            cameras=base.cameras,
            control_rate_hz=base.control_rate_hz,
            image_size=base.image_size,
            max_joint_speed=speeds,
        )
        self.settings = settings_for(self.rig)
        self.xml = self._scene_xml()
        self._model: Any = None
        self._data: Any = None
        self._renderer: Any = None
        self._extra_renderers: dict[tuple[int, int], Any] = {}
        self._target = HOME_Q14.copy()
        self.layout: Layout | None = None
        self.subtask: Subtask | None = None
        self.steps = 0  # control steps since the last reset
        self.look: Look | None = None  # the varied look of this episode (None under "flat")
        self._frame = 0  # control steps since reset() began, lead-in included: keys a frame's camera noise

    # ------------------------------------------------------------------ Robot contract

    @property
    def spec(self) -> RobotSpec:
        return self._spec

    @property
    def is_connected(self) -> bool:
        return self._model is not None

    def connect(self) -> None:
        if self._model is not None:
            return
        assets: dict[str, bytes] = {}
        for board in (self.board_mount, self.table_board, self.hand_board):
            if board is not None:
                assets.update(board.assets())
        assets.update(scene_assets(self.task.objects(), self.task.fixtures()).files)
        assets.update(appearance_assets(self.task.objects(), self.task.fixtures(), self.appearance).files)
        model = compile_scene(self.xml, f"sim rig {self.rig.name!r} with task {self.task.name!r}", assets or None)
        self._model = model
        self._data = mujoco.MjData(model)
        w, h = self._spec.image_size
        self._renderer = make_renderer(model, w, h)
        self._index_model()
        self.reset(seed=0, subtask=0, history=0)

    def disconnect(self) -> None:
        for renderer in (self._renderer, *self._extra_renderers.values()):
            if renderer is not None:
                renderer.close()
        self._extra_renderers = {}
        self._model = self._data = self._renderer = None

    def __enter__(self) -> SimRobot:
        self.connect()
        return self

    def __exit__(
        self, exc_type: type[BaseException] | None, exc: BaseException | None, tb: TracebackType | None
    ) -> None:
        self.disconnect()

    def _require(self) -> None:
        if self._model is None:
            raise DeviceNotConnectedError(f"sim:{self.rig.name}", "not connected; call connect() first")

    def _index_model(self) -> None:
        m = self._model
        self._arm_qadr = {
            side: np.array([m.joint(f"{side}_joint_{i}").qposadr[0] for i in range(1, 7)]) for side in ARM_SIDES
        }
        self._arm_dadr = {
            side: np.array([m.joint(f"{side}_joint_{i}").dofadr[0] for i in range(1, 7)]) for side in ARM_SIDES
        }
        self._finger_qadr = {
            side: np.array([m.joint(f"{side}_finger_{f}").qposadr[0] for f in "ab"]) for side in ARM_SIDES
        }
        self._act = {side: np.array([m.actuator(f"{side}_joint_{i}").id for i in range(1, 7)]) for side in ARM_SIDES}
        self._finger_act = {side: np.array([m.actuator(f"{side}_finger_{f}").id for f in "ab"]) for side in ARM_SIDES}
        self._half_open = {side: getattr(self.rig.arms, side).gripper.max_opening_m / 2 for side in ARM_SIDES}
        self._obj_body = {o.name: m.body(o.name).id for o in self.task.objects()}
        self._obj_qadr = {o.name: m.joint(f"{o.name}_free").qposadr[0] for o in self.task.objects()}
        self._finger_body = {side: (m.body(f"{side}_finger_a").id, m.body(f"{side}_finger_b").id) for side in ARM_SIDES}

    def state(self) -> NDArray[np.float32]:
        """The measured 14-d state: joint angles and the normalised finger gap of each gripper."""
        self._require()
        q = self._data.qpos
        out = np.empty(STATE_DIM, dtype=np.float64)
        for side, (arm, grip) in ARM_LAYOUT.items():
            out[arm] = q[self._arm_qadr[side]]
            # Clipped like a real gripper's position report: contact can push a finger a hair past its stop.
            gap = q[self._finger_qadr[side]].sum() / (2 * self._half_open[side])
            out[grip] = min(1.0, max(0.0, gap))
        return out.astype(np.float32)

    def render(self, camera: str, width: int | None = None, height: int | None = None) -> NDArray[np.uint8]:
        """One RGB frame of ``camera``; ``width``/``height`` (default: the rig's image size) keep the field of view.

        A MuJoCo camera's ``fovy`` spans the full image height, so a larger render is the same camera with its
        intrinsics scaled (``CameraModel.resized``): what a calibration needs from a full-resolution camera.
        """
        self._require()
        size = (width or self._spec.image_size[0], height or self._spec.image_size[1])
        renderer = self._renderer
        if size != tuple(self._spec.image_size):
            _check_int("width", size[0], minimum=1)
            _check_int("height", size[1], minimum=1)
            renderer = self._extra_renderers.get(size)
            if renderer is None:
                vis = self._model.vis.global_  # the offscreen buffer must hold the frame
                vis.offwidth, vis.offheight = max(vis.offwidth, size[0]), max(vis.offheight, size[1])
                renderer = self._extra_renderers[size] = make_renderer(self._model, *size)
        renderer.update_scene(self._data, camera=camera)
        image = np.array(renderer.render(), dtype=np.uint8, copy=True)
        if self.look is not None:
            image = camera_effects(image, self.look, frame=self._frame, camera=camera)
        return image

    def observe(self) -> Observation:
        self._require()
        images = {cam: self.render(cam) for cam in self._spec.cameras}
        return Observation(images=images, state=self.state(), timestamp=float(self._data.time))

    def clamp(self, action: NDArray[np.floating]) -> NDArray[np.float64]:
        """The command after joint limits and the per-step speed limit (relative to the last command)."""
        a = np.asarray(action, dtype=np.float64)
        if a.shape != (STATE_DIM,):
            raise ValueError(f"action: expected shape ({STATE_DIM},), got {a.shape}")
        if not np.all(np.isfinite(a)):
            raise ValueError(f"action: must be finite, got {a.tolist()}")
        a = np.clip(a, self._spec.lower_array, self._spec.upper_array)
        step = np.asarray(self._spec.max_joint_speed) / self._spec.control_rate_hz
        return np.clip(a, self._target - step, self._target + step)

    def send_action(self, action: NDArray[np.floating]) -> NDArray[np.float32]:
        """Track one absolute 14-d command for one control step; returns the command actually applied."""
        self._require()
        new = self.clamp(action)
        old = self._target
        n = self.settings.substeps
        for k in range(1, n + 1):
            self._apply_ctrl(old + (new - old) * (k / n))
            mujoco.mj_step(self._model, self._data)
        self._target = new
        self.steps += 1
        self._frame += 1
        return new.astype(np.float32)

    def _apply_ctrl(self, target: NDArray[np.float64], data: Any = None) -> None:
        d = self._data if data is None else data
        for side, (arm, grip) in ARM_LAYOUT.items():
            d.ctrl[self._act[side]] = target[arm]
            half = self._half_open[side]
            d.ctrl[self._finger_act[side]] = target[grip] * (half + FINGER_SQUEEZE) - FINGER_SQUEEZE

    # ------------------------------------------------------------------ sim-only extras

    @property
    def time(self) -> float:
        self._require()
        return float(self._data.time)

    def clock(self) -> float:
        """The robot's clock for the safety filter: simulated seconds, the units of ``observe().timestamp``."""
        return self.time

    def command(self) -> NDArray[np.float32]:
        """The last applied command (the target the servos track)."""
        return self._target.astype(np.float32)

    def reset(
        self,
        seed: int = 0,
        subtask: int = 0,
        *,
        task: str | Path | Task | None = None,
        history: int = 5,
        stride: int = 3,
    ) -> Start:
        """Lay out the task for ``seed`` with subtasks before ``subtask`` done; return the shared start.

        ``task`` switches to another task first (the scene is rebuilt: ~0.2 s). The arms begin slightly
        away from home (seeded) and move home over ``history·stride`` control steps while the history
        frames are recorded every ``stride`` steps (oldest first); the start observation follows the
        last step. With ``history=0`` the arms start at home. Under the ``varied`` appearance the
        episode's :class:`~simrig.appearance.Look` is drawn from ``(seed, subtask)`` here.
        """
        self._require()
        if task is not None:
            new = task if isinstance(task, Task) else make_task(task)
            if new.digest != self.task.digest:
                new.check_index(subtask)
                self.disconnect()
                self.task = new
                self.xml = self._scene_xml()
                self.connect()
        self.task.check_index(subtask)
        _check_int("history", history, minimum=0)
        _check_int("stride", stride, minimum=1)
        if isinstance(seed, bool) or not isinstance(seed, int):
            raise ValueError(f"seed: expected an integer, got {seed!r}")
        m, d = self._model, self._data
        mujoco.mj_resetData(m, d)
        self.layout = self.task.layout(seed)
        self.set_object_poses(self.task.completed_poses(self.layout, subtask))
        self._frame = 0
        if self.appearance == "varied":  # lights and table material only: physics never reads them
            self.look = draw_look(seed, subtask)
            apply_look(m, self.look)
        rng = np.random.default_rng([seed, subtask, 7])
        start_q = HOME_Q14.copy()
        if history > 0:  # the lead-in moves home from a seeded perturbation; without one, start at home
            for arm in (LEFT_ARM, RIGHT_ARM):
                start_q[arm] += rng.uniform(-0.12, 0.12, 6) * np.array([1, 1, 1, 0.5, 0.5, 0.5])
        self._set_arm_qpos(start_q)
        self._target = start_q.copy()
        self._apply_ctrl(start_q)
        mujoco.mj_forward(m, d)
        for _ in range(round(SETTLE_S * self._spec.control_rate_hz) * self.settings.substeps):
            mujoco.mj_step(m, d)
        d.time = 0.0
        frames = []
        n = history * stride
        for k in range(n):
            if k % stride == 0:
                frames.append(self.observe())
            self.send_action(start_q + (HOME_Q14 - start_q) * ((k + 1) / n))
        self.steps = 0
        self.subtask = Subtask(task=self.task.name, index=subtask, instruction=self.task.instruction, seed=seed)
        return Start(subtask=self.subtask, observation=self.observe(), history=tuple(frames))

    def _scene_xml(self) -> str:
        return build_mjcf(
            self.rig,
            self.task.objects(),
            self.task.fixtures(),
            board_mount=self.board_mount,
            table_board=self.table_board,
            hand_board=self.hand_board,
            appearance=self.appearance,
        )

    def set_boards(self, *, board_mount: BoardMount | None = None, hand_board: HandBoard | None = None) -> None:
        """Put a calibration board on a gripper or in a person's hand (or take it away): the scene is rebuilt.

        What an operator does between calibration steps. The arms stay where they stand and keep their
        target; the task's objects are laid out anew (seed 0). The table board, if any, stays.
        """
        self._require()
        q = self.state().astype(np.float64)
        target = self._target.copy()
        self.disconnect()
        self.board_mount, self.hand_board = board_mount, hand_board
        self.xml = self._scene_xml()
        self.connect()
        self._set_arm_qpos(q)
        self._target = target
        self._apply_ctrl(target)
        mujoco.mj_forward(self._model, self._data)

    def hold_board(self, T_rig_board: npt.ArrayLike | None) -> None:
        """Hold the hand board at ``T_rig_board`` (board frame → rig frame), or park it out of sight (None)."""
        self._require()
        if self.hand_board is None:
            raise ValueError("hold_board: this scene has no hand board (set_boards(hand_board=...) first)")
        body = self._model.body(self.hand_board.body)
        mocap = int(body.mocapid[0])
        if T_rig_board is None:
            self._data.mocap_pos[mocap] = PARKED
            self._data.mocap_quat[mocap] = (1.0, 0.0, 0.0, 0.0)
        else:
            T = np.asarray(T_rig_board, dtype=np.float64)
            if T.shape != (4, 4) or not is_rigid_transform(T):
                raise ValueError(f"hold_board: expected a rigid 4x4 transform, got {T.tolist()}")
            quat = np.empty(4)
            mujoco.mju_mat2Quat(quat, np.ascontiguousarray(T[:3, :3]).reshape(9))
            self._data.mocap_pos[mocap] = T[:3, 3]
            self._data.mocap_quat[mocap] = quat
        mujoco.mj_forward(self._model, self._data)

    def _set_arm_qpos(self, q14: NDArray[np.float64]) -> None:
        d = self._data
        for side, (arm, grip) in ARM_LAYOUT.items():
            d.qpos[self._arm_qadr[side]] = q14[arm]
            d.qpos[self._finger_qadr[side]] = q14[grip] * self._half_open[side]
            d.qvel[self._arm_dadr[side]] = 0.0

    def set_object_poses(self, poses: dict[str, ObjectPose]) -> None:
        """Teleport objects (privileged; used to build subtask starts and in tests)."""
        self._require()
        for name, pose in poses.items():
            adr = self._obj_qadr[name]
            self._data.qpos[adr : adr + 3] = pose.xyz
            self._data.qpos[adr + 3 : adr + 7] = pose.quat
        mujoco.mj_forward(self._model, self._data)

    def object_poses(self, data: Any = None) -> dict[str, ObjectPose]:
        """Privileged object poses (for judges and tests, never for policies)."""
        self._require()
        d = self._data if data is None else data
        out = {}
        for name, body in self._obj_body.items():
            x = d.xpos[body]
            q = d.xquat[body]
            out[name] = ObjectPose(
                (float(x[0]), float(x[1]), float(x[2])), (float(q[0]), float(q[1]), float(q[2]), float(q[3]))
            )
        return out

    def task_state(self) -> dict[str, Any]:
        """Privileged task state for judges and logs (JSON-friendly): layout, object poses, placements.

        ``placed[k]`` says whether subtask k's object sits at its goal right now (no settling check;
        use :meth:`check_subtask` for the full verdict).
        """
        self._require()
        if self.layout is None or self.subtask is None:
            raise ValueError("task_state: no task laid out; call reset() first")
        poses = self.object_poses()
        placed = [self.task.in_place(self.layout, poses, k).in_place for k in range(self.task.num_subtasks)]
        return {
            "task": self.task.name,
            "seed": self.layout.seed,
            "subtask": self.subtask.index,
            "time": self.time,
            "objects": {n: {"xyz": list(p.xyz), "quat": list(p.quat)} for n, p in poses.items()},
            "placed": placed,
            "held": {n: self.held_by(n) for n in poses},
        }

    def held_by(self, name: str, data: Any = None) -> str | None:
        """The arm whose two fingers both touch object ``name`` (a pinch), or None.

        A single finger or the palm brushing an object while the gripper works on another one is not
        holding it; an object resting on a gripper is caught by the settling check instead.
        """
        self._require()
        d = self._data if data is None else data
        body = self._obj_body[name]
        touched: set[int] = set()
        for i in range(d.ncon):
            c = d.contact[i]
            b1, b2 = int(self._model.geom_bodyid[c.geom1]), int(self._model.geom_bodyid[c.geom2])
            if b1 == body:
                touched.add(b2)
            elif b2 == body:
                touched.add(b1)
        for side in ARM_SIDES:
            if {self._finger_body[side][0], self._finger_body[side][1]} <= touched:
                return side
        return None

    def check_subtask(self, index: int | None = None, settle_s: float | None = None) -> SubtaskCheck:
        """Privileged success of a subtask now: in place, released, and still in place after settling.

        Settling runs on a copy of the physics state with the arms holding their last command, so the
        episode itself is not changed; how long, and how far the object may move meanwhile, is the
        subtask's ``settle`` in the task file (``settle_s`` overrides the time).
        """
        self._require()
        if index is None:
            if self.subtask is None:
                raise ValueError("check_subtask: no subtask; call reset() first or pass index")
            index = self.subtask.index
        self.task.check_index(index)
        assert self.layout is not None
        name = self.task.subtask_object(index)
        settle = self.task.subtask(index).settle
        settle_s = settle.seconds if settle_s is None else settle_s
        now = self.task.in_place(self.layout, self.object_poses(), index)
        holder = self.held_by(name)
        released = holder is None
        copy = mujoco.MjData(self._model)
        # A full copy (warm-start and contact state included): resting stacks must stay at rest.
        mujoco.mj_copyData(copy, self._model, self._data)
        self._apply_ctrl(self._target, copy)
        before = self.object_poses(copy)[name].position
        for _ in range(round(settle_s / self._model.opt.timestep)):
            mujoco.mj_step(self._model, copy)
        after_poses = self.object_poses(copy)
        later = self.task.in_place(self.layout, after_poses, index)
        moved = float(np.linalg.norm(after_poses[name].position - before))
        stable = later.in_place and moved < settle.max_motion
        success = now.in_place and released and stable
        if not now.in_place:
            reason = now.reason
        elif not released:
            reason = f"{name} is still held by the {holder} gripper"
        elif not stable:
            reason = f"{name} did not stay in place ({later.reason}; moved {moved * 100:.1f} cm)"
        else:
            reason = now.reason
        return SubtaskCheck(success=success, in_place=now.in_place, released=released, stable=stable, reason=reason)
