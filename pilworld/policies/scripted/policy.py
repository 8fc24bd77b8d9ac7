"""``ScriptedPolicy``: an observation-only pick-and-place policy for the simulated rig's tasks.

Each call sees an :class:`~pilworld.types.Observation` (the head-camera image and the 14-d measured
state) and the instruction — never the simulator — and returns ``H_π × 14`` absolute joint commands:

1. perceive: find each object by colour in ``cam_high`` and back-project it through the rig's
   ``CameraModel`` (:mod:`pilworld.policies.scripted.knowledge`);
2. decide: the task's next pick-and-place from those positions, or "done";
3. act: if a gripper is holding something (its measured opening lies between empty-closed and open),
   carry to the goal, lower, release and retreat; otherwise approach, descend, close and lift — then
   continue into the carry in the same chunk (a chunked policy commits to its plan until the next
   query). The other arm returns home. Motions are solved with closed-form IK.

Its only memory is where objects were last fully seen (objects vanish under a gripper seen from above),
which object it last went to grasp (the fingers hide what they hold) and which objects looked finished
in the last clear view; call
:meth:`ScriptedPolicy.reset` at the start of each subtask or episode.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from pilworld.config.rig import RigConfig
from pilworld.policies.scripted.knowledge import (
    Intent,
    Sightings,
    TaskKnowledge,
    knowledge_for,
    knowledge_for_instruction,
)
from pilworld.policies.scripted.motion import ArmPlanner, Waypoint, nearest_equivalent_yaw, tcp_yaw
from pilworld.policies.scripted.skill import Checkpoint, checkpoint, errors_for
from pilworld.types import ARM_LAYOUT, HEAD_VIEW, STATE_DIM, Observation
from simrig.tasks import Task

APPROACH_Z = 0.12  # TCP height for moving over objects [m]
NOMINAL_SPEED = 0.6  # peak Cartesian TCP speed of the best checkpoint [m/s]
HOLD_MIN, HOLD_MAX = 0.06, 0.85  # measured grip between these: the fingers rest on an object
FINGERTIP_BELOW_TCP = 0.018  # the fingertips reach this far below the TCP [m]
FINGER_THICKNESS = 0.01  # each finger pad, outward from the gap between the fingers [m]


def _home() -> NDArray[np.float64]:
    # The simulated rig's home pose (simrig.robot.HOME_Q14), as a policy's "rest" prior.
    from simrig.poses import HOME_Q14

    return HOME_Q14.copy()


class ScriptedPolicy:
    """A scripted checkpoint; ``infer(observation, instruction) -> float32[horizon, 14]``."""

    def __init__(
        self,
        rig: RigConfig,
        ckpt: str | Checkpoint = "scripted_step_30k",
        *,
        seed: int = 0,
        horizon: int = 50,
        task: Task | str | Path | None = None,
    ) -> None:
        self.rig = rig
        self.checkpoint = checkpoint(ckpt) if isinstance(ckpt, str) else ckpt
        self.horizon = horizon
        self.camera = rig.head_camera_model
        spec = rig.robot_spec()
        lo, hi = spec.lower_array.astype(np.float64), spec.upper_array.astype(np.float64)
        kin = rig.kinematics
        self.planners = {
            side: ArmPlanner(getattr(kin, side), rig.control_rate_hz, lo[arm], hi[arm])
            for side, (arm, _) in ARM_LAYOUT.items()
        }
        self.home = _home()
        # Each arm's home TCP (position, yaw), where it retreats to after a placement.
        self._home_tcp: dict[str, tuple[tuple[float, float, float], float]] = {}
        for side, (arm, _) in ARM_LAYOUT.items():
            T = self.planners[side].tcp(self.home[arm])
            self._home_tcp[side] = ((float(T[0, 3]), float(T[1, 3]), float(T[2, 3])), tcp_yaw(T))
        self._knowledge: dict[str, TaskKnowledge] = {}
        # A stand-in for a VLA trained on one task: given its task file, it acts on it whatever the
        # instruction's wording; without one it recognises a packaged task by its instruction.
        self._task: TaskKnowledge | None = None if task is None else knowledge_for(task)
        self.seed = seed
        self.sightings = Sightings(image_width=self.camera.width)
        self._grasped: str | None = None  # the object this policy last went to grasp
        self._done: dict[str, bool] = {}  # per object: finished, as last judged from a clear view

    @property
    def name(self) -> str:
        return self.checkpoint.name

    def reset(self, seed: int | None = None) -> None:
        """Forget remembered sightings; ``seed`` draws this episode's mistakes (see ``skill.py``)."""
        if seed is not None:
            self.seed = seed
        self.sightings = Sightings(image_width=self.camera.width)
        self._grasped = None
        self._done = {}

    def knowledge(self, instruction: str) -> TaskKnowledge:
        if self._task is not None:
            return self._task
        if instruction not in self._knowledge:
            self._knowledge[instruction] = knowledge_for_instruction(instruction)
        return self._knowledge[instruction]

    # ------------------------------------------------------------------ inference

    def infer(self, observation: Observation, instruction: str) -> NDArray[np.float32]:
        if HEAD_VIEW not in observation.images:
            raise ValueError(f"observation: the scripted policy needs the {HEAD_VIEW!r} image, got {observation.views}")
        state = np.asarray(observation.state, dtype=np.float64)
        if state.shape != (STATE_DIM,):
            raise ValueError(f"observation.state: expected {STATE_DIM} values, got shape {state.shape}")
        know = self.knowledge(instruction)
        tcps = np.stack([self.planners[side].tcp(state[arm])[:3, 3] for side, (arm, _) in ARM_LAYOUT.items()])
        grippers_uv, _ = self.camera.project(tcps)
        self.sightings.update(np.asarray(observation.images[HEAD_VIEW]), know.classes, grippers_uv)
        holding = [side for side, (_, grip) in ARM_LAYOUT.items() if HOLD_MIN < state[grip] < HOLD_MAX]
        if holding:
            side_index = list(ARM_LAYOUT).index(holding[0])
            held = self._grasped or self._held_object(know, grippers_uv[side_index])
            intent = None if held is None else know.intent_for(held, self.sightings, self.camera)
        else:
            intent = self._next_intent(know, tcps)
            if intent is not None and self.sightings.last.get(intent.obj) is None:
                # Out of sight. Under a gripper where we remember it (we are reaching for it): trust the
                # memory. Elsewhere the memory may be stale (it was moved out of view): clear the view.
                remembered = np.asarray(intent.grasp_xyz[:2])
                if min(float(np.hypot(*(t[:2] - remembered))) for t in tcps) > 0.03:
                    intent = None
            self._grasped = None if intent is None else intent.obj
        chunk = np.empty((self.horizon, STATE_DIM), dtype=np.float64)
        active: str | None = None
        if intent is not None:
            active = holding[0] if holding else self._arm_for(intent)
            arm, grip = ARM_LAYOUT[active]
            plan = self._pick_and_place(active, state[arm], state[grip], intent, know, carrying=bool(holding))
            chunk[:, arm], chunk[:, grip] = plan[:, :6], plan[:, 6]
        for side, (arm, grip) in ARM_LAYOUT.items():
            if side == active:
                continue
            chunk[:, np.r_[arm, grip]] = self._retreat(side, state[arm], state[grip])
        return chunk.astype(np.float32)

    def _next_intent(self, know: TaskKnowledge, tcps: NDArray[np.float64]) -> Intent | None:
        """The first unfinished object's pick-and-place, with "done" judged only from clear views.

        An arm over an object hides part of it from the head camera and skews its estimate; then the
        object keeps the verdict of the last clear view instead of flipping to "not done" and being
        picked up again. "Clear" means no gripper within 12 cm and no forearm passing within 8 cm
        (the segment from a gripper to its arm's base, on the table plane).
        """
        for name, intent, done in know.progress(self.sightings, self.camera):
            uv = self.sightings.uv.get(name)
            clear = uv is None or self._clear_of_arms(uv, tcps)
            if clear or name not in self._done:
                self._done[name] = done
            if not self._done[name]:
                return intent
        return None

    def _clear_of_arms(self, uv: NDArray[np.float64], tcps: NDArray[np.float64]) -> bool:
        pts, ok = self.camera.backproject_to_plane(uv, 0.03)
        if not bool(ok):
            return False
        p = np.asarray(pts[:2], dtype=np.float64)
        for side, tcp in zip(ARM_LAYOUT, tcps, strict=True):
            a = np.asarray(tcp[:2], dtype=np.float64)
            b = getattr(self.rig.kinematics, side).T_rig_base[:2, 3]
            if float(np.hypot(*(p - a))) < 0.12:
                return False
            t = float(np.clip(np.dot(p - a, b - a) / max(float(np.dot(b - a, b - a)), 1e-9), 0.0, 1.0))
            if float(np.hypot(*(p - (a + t * (b - a))))) < 0.08:
                return False
        return True

    def _held_object(self, know: TaskKnowledge, gripper_uv: NDArray[np.float64]) -> str | None:
        """The unfinished object whose blob lies nearest the holding gripper (at ``gripper_uv``) in the image."""
        best, best_d = None, math.inf
        progress = know.progress(self.sightings, self.camera)
        done = {name for name, _, ok in progress if ok}
        movable = {name for name, _, _ in progress}
        for c in know.classes:
            blob = self.sightings.last.get(c.name)
            if blob is None or c.name in done or c.name not in movable:
                continue
            d = float(np.hypot(*(np.asarray(blob.centroid_uv) - gripper_uv)))
            if d < best_d:
                best, best_d = c.name, d
        return best

    def _home_xyz(self, side: str) -> tuple[float, float, float]:
        return self._home_tcp[side][0]

    def _home_yaw(self, side: str) -> float:
        return self._home_tcp[side][1]

    def _arm_for(self, intent: Intent) -> str:
        return "left" if intent.grasp_xyz[1] >= 0.0 else "right"

    def _retreat(self, side: str, q: NDArray[np.float64], grip: float) -> NDArray[np.float64]:
        """Back to home in Cartesian space, first straight up: a joint-space move could dip into a stack."""
        arm, g = ARM_LAYOUT[side]
        planner = self.planners[side]
        T = planner.tcp(q)
        home = self._home_xyz(side)
        if float(np.linalg.norm(T[:3, 3] - np.asarray(home))) < 0.01:
            return planner.joint_path(q, grip, self.home[arm], float(self.home[g]), self.horizon)
        safe = max(float(T[2, 3]), APPROACH_Z, home[2])
        # The gripper is symmetric under a half turn: keep the nearer of the two home yaws.
        yaw = nearest_equivalent_yaw(self._home_yaw(side), tcp_yaw(T), math.pi)
        wps = [
            Waypoint((float(T[0, 3]), float(T[1, 3]), safe), tcp_yaw(T), 1.0, speed=0.3),
            Waypoint((home[0], home[1], safe), yaw, 1.0, speed=NOMINAL_SPEED),
            Waypoint(home, yaw, 1.0, speed=0.3),
        ]
        return planner.plan(q, grip, wps, self.horizon)

    def _pick_and_place(
        self,
        side: str,
        q: NDArray[np.float64],
        grip: float,
        intent: Intent,
        know: TaskKnowledge,
        *,
        carrying: bool,
    ) -> NDArray[np.float64]:
        planner = self.planners[side]
        err = errors_for(self.checkpoint.skill, self.seed, intent.obj)
        v = NOMINAL_SPEED * err.speed
        T = planner.tcp(q)
        pos, yaw_now = T[:3, 3], tcp_yaw(T)
        gx, gy, gz = intent.grasp_xyz
        gx, gy = gx + err.grasp_offset[0], gy + err.grasp_offset[1]
        offset = np.zeros(2)
        release_z = intent.release_z
        grasp = know.geometry(intent.obj).grasp
        member = know.member(intent.obj)
        inside = grasp.kind == "pinch" and member is not None and member.kind == "inside"
        if inside and member is not None and not self._fingers_fit(side, know, member.target):
            # Into a container narrower than the open fingers: let go with the fingertips above its rim.
            # Opened inside it, the fingers would push its wall and drag the object out again.
            release_z = max(release_z, know.target_top(member) + FINGERTIP_BELOW_TCP + 0.008)
        if grasp.kind == "rim" and member is not None:
            base_xy = getattr(self.rig.kinematics, side).T_rig_base[:2, 3]
            (gx, gy, gz), yaw, off = know.rim_grasp(intent.obj, np.array([gx, gy]), base_xy)
            offset = np.asarray(off)
            release_z = member.rest + grasp.height + 0.01
            if member.kind != "region":
                # Open with the fingertips above the rim below: opened inside it, the outer finger would
                # wedge against its wall and lift the whole stack on the way up.
                release_z = max(release_z, know.target_top(member) + FINGERTIP_BELOW_TCP + 0.008)
            if carrying:
                # Keep the yaw we hold it with; the container's centre lies along the closing axis.
                yaw = yaw_now
                offset = self._held_offset(know, intent, pos, yaw_now)
        elif grasp.symmetry == math.pi:
            # An oblong object: close across its short side, whatever its yaw on the table.
            long_yaw = self._seen_long_axis(know, intent.obj, grasp.long_axis_yaw)
            yaw = nearest_equivalent_yaw(long_yaw, yaw_now, math.pi) if not carrying else yaw_now
        else:
            yaw = nearest_equivalent_yaw(0.0, yaw_now, math.pi / 2)
        yaw = nearest_equivalent_yaw(yaw, yaw_now, math.pi)
        goal = np.asarray(intent.goal_xy) + np.asarray(err.place_offset) - offset
        rz = release_z + err.release_extra
        high = max(APPROACH_Z, rz + 0.05)  # travel height: clear of the tallest stack it builds
        carry = [
            Waypoint((float(goal[0]), float(goal[1]), high), yaw, 0.0, speed=v),
            Waypoint((float(goal[0]), float(goal[1]), rz), yaw, 0.0, speed=0.6 * v),
            Waypoint((float(goal[0]), float(goal[1]), rz), yaw, 1.0, speed=v, dwell=4),
            Waypoint((float(goal[0]), float(goal[1]), high), yaw, 1.0, speed=v),
            # Clear the view: a gripper hovering over what it placed hides it from the head camera.
            Waypoint(self._home_xyz(side), self._home_yaw(side), 1.0, speed=v),
        ]
        if carrying:
            far = float(np.hypot(*(pos[:2] - goal))) > 0.015
            lift = (
                [Waypoint((float(pos[0]), float(pos[1]), high), yaw_now, 0.0, speed=0.6 * v)]
                if far and pos[2] < high - 0.03
                else []
            )
            return planner.plan(q, 0.0, lift + (carry if far else carry[1:]), self.horizon)
        aligned = (
            float(np.hypot(pos[0] - gx, pos[1] - gy)) < 0.01
            and abs(nearest_equivalent_yaw(yaw, yaw_now, 2 * math.pi) - yaw_now) < 0.1
        )
        wps: list[Waypoint] = []
        if not aligned and pos[2] < high - 0.03:
            wps.append(Waypoint((float(pos[0]), float(pos[1]), high), yaw_now, 1.0, speed=0.6 * v))
        wps += [
            Waypoint((gx, gy, high), yaw, 1.0, speed=v),
            Waypoint((gx, gy, gz), yaw, 1.0, speed=0.6 * v),
            Waypoint((gx, gy, gz), yaw, 0.0, speed=v, dwell=8),
            Waypoint((gx, gy, high), yaw, 0.0, speed=0.6 * v),
        ]
        if aligned:
            # Already above the grasp: go down, or, already down there, close right away (a grasp
            # started in the previous chunk must not be undone by reopening).
            wps = wps[2:] if abs(pos[2] - gz) < 0.01 else wps[1:]
        return planner.plan(q, grip if aligned else 1.0, wps + carry, self.horizon)

    def _fingers_fit(self, side: str, know: TaskKnowledge, container: str) -> bool:
        """Whether the fully open fingers fit inside ``container``'s opening, with a centimetre to spare."""
        inside = know.geometry(container).container
        half_open = getattr(self.rig.arms, side).gripper.max_opening_m / 2
        return inside is not None and inside.opening >= half_open + FINGER_THICKNESS + 0.01

    def _held_offset(
        self, know: TaskKnowledge, intent: Intent, tcp: NDArray[np.float64], yaw: float
    ) -> NDArray[np.float64]:
        """The held container's centre relative to the TCP: ±r along the closing axis, the sign from the image."""
        grasp = know.geometry(intent.obj).grasp
        r = grasp.radius
        axis = np.array([math.sin(yaw), -math.cos(yaw)])
        base_z = tcp[2] - grasp.height  # the held container's underside
        seen = know.held_xy(self.sightings, self.camera, intent.obj, base_z + 0.02)
        cands = [r * axis, -r * axis]
        if seen is None or not np.all(np.isfinite(seen)):
            return cands[0]
        return min(cands, key=lambda c: float(np.hypot(*(tcp[:2] + c - seen))))

    def _seen_long_axis(self, know: TaskKnowledge, obj: str, default: float) -> float:
        """The yaw of an oblong object's long side on the table, from its blob's spread (back-projected)."""
        blob = self.sightings.last.get(obj)
        if blob is None or blob.n_pixels < 6:
            return default
        g = know.geometry(obj)
        pts, ok = self.camera.backproject_to_plane(blob.pixels_uv.astype(np.float64), g.bottom + g.mid)
        xy = np.asarray(pts, dtype=np.float64)[np.asarray(ok, dtype=bool)][:, :2]
        if len(xy) < 6:
            return default
        cov = np.cov((xy - xy.mean(axis=0)).T)
        w, v = np.linalg.eigh(cov)
        major = v[:, int(np.argmax(w))]
        return math.atan2(float(major[1]), float(major[0]))
