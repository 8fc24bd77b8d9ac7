"""Robot-driven board views on a hardware rig: plan, confirm, move pose by pose, record each view at once, resume.

Used by ``pilworld calibrate handeye`` (views to calibrate with) and ``pilworld calibrate check`` (held-out
views) on a rig with a ``hardware:`` section. The folder it writes is the recording format of
:mod:`.recording` (``NNN.png`` + ``poses.json``, readable by ``--from`` and ``check --images``) plus
``plan.json``: the planned commands per arm and what became of each pose (recorded, or skipped and why).

* Every view is written the moment it is taken (the PNG, then ``poses.json`` rewritten atomically), so a
  fault, a refusal or Ctrl-C loses nothing that was recorded.
* ``resume``: the plan is read back from ``plan.json`` (not re-planned: the arm now stands elsewhere), poses
  already recorded or skipped are passed over, and the collection continues with the next one.
* A pose is **skipped and reported**, and the collection goes on, when the safety filter refuses its
  target (outside the joint limits) or its path (:func:`~.rig_motion.path_problem`, direct and through the
  hold pose). A device fault (protective stop, a stalled camera, a lost connection) or Ctrl-C **stops** the
  collection: the drivers have stopped the arms; :class:`~.rig_devices.CollectionStoppedError` names it.
"""

from __future__ import annotations

import json
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Final

import cv2
import numpy as np
import numpy.typing as npt

from calib.board import ChArUcoBoard
from hw_drivers.errors import RobotError, SafetyViolationError
from hw_drivers.safety import SafetyFilter
from pilworld.calibration.plan import PosePlan
from pilworld.calibration.recording import POSES_FILE, RECORDING_FORMAT, RecordedView, board_to_dict
from pilworld.calibration.rig_devices import CollectionStoppedError, RigRobot
from pilworld.calibration.rig_motion import MoveSettings, move_duration, paced_move, path_problem
from pilworld.types import ARM_LAYOUT, HEAD_VIEW

__all__ = ["PLAN_FILE", "ArmPlan", "CollectionPlan", "ViewStore", "collect_on_rig", "plan_text"]

FloatArray = npt.NDArray[np.float64]

PLAN_FILE: Final = "plan.json"
PLAN_FORMAT: Final = "pilworld.rig_collection_plan/v1"


@dataclass
class ArmPlan:
    """One arm's planned commands (14-d, in visiting order) and the board poses they should show."""

    arm: str
    commands: list[list[float]]
    summary: str = ""

    @classmethod
    def from_pose_plan(cls, plan: PosePlan, hold: npt.ArrayLike) -> ArmPlan:
        return cls(plan.arm, plan.states(hold).tolist(), plan.summary())


@dataclass
class CollectionPlan:
    """Every arm's plan, the hold pose the collection starts from, and each pose's outcome (by view name)."""

    purpose: str  #: "handeye" or "check"
    hold: list[float]
    arms: list[ArmPlan]
    outcome: dict[str, str] = field(default_factory=dict)  #: pose name → "recorded" or "skipped: reason"
    settings: dict[str, Any] = field(default_factory=dict)

    def pose_names(self, arm: ArmPlan) -> list[str]:
        return [f"{arm.arm}_{i:03d}" for i in range(len(arm.commands))]

    def remaining(self) -> int:
        return sum(n not in self.outcome for a in self.arms for n in self.pose_names(a))

    def save(self, folder: Path) -> None:
        doc = {
            "format": PLAN_FORMAT,
            "purpose": self.purpose,
            "hold": self.hold,
            "arms": [a.__dict__ for a in self.arms],
            "outcome": self.outcome,
            "settings": self.settings,
        }
        _write_json(folder / PLAN_FILE, doc)

    @classmethod
    def load(cls, folder: Path) -> CollectionPlan:
        path = folder / PLAN_FILE
        if not path.is_file():
            raise FileNotFoundError(f"--resume: {folder} has no {PLAN_FILE} (nothing to resume; run without --resume)")
        doc = json.loads(path.read_text(encoding="utf-8"))
        if doc.get("format") != PLAN_FORMAT:
            raise ValueError(f"{path}: field 'format': expected {PLAN_FORMAT!r}, got {doc.get('format')!r}")
        arms = [ArmPlan(**a) for a in doc["arms"]]
        return cls(doc["purpose"], doc["hold"], arms, dict(doc.get("outcome", {})), dict(doc.get("settings", {})))


def _write_json(path: Path, doc: Any) -> None:
    """Write ``doc`` atomically: a crash leaves the old file or the new one, never half of one."""
    tmp = path.with_name(path.name + ".tmp")
    tmp.write_text(json.dumps(doc, indent=1) + "\n", encoding="utf-8")
    tmp.replace(path)


class ViewStore:
    """A recording folder that grows one view at a time (the format of :class:`.recording.Recording`)."""

    def __init__(self, folder: Path, rig: str, board: ChArUcoBoard, extra: dict[str, Any] | None = None) -> None:
        self.folder = folder
        folder.mkdir(parents=True, exist_ok=True)
        path = folder / POSES_FILE
        if path.is_file():
            self.doc: dict[str, Any] = json.loads(path.read_text(encoding="utf-8"))
        else:
            self.doc = {"format": RECORDING_FORMAT, "rig": rig, "board": board_to_dict(board), "image_size": None}
            self.doc["views"] = []
            self.doc.update(extra or {})

    @property
    def count(self) -> int:
        return len(self.doc["views"])

    def add(self, view: RecordedView, pose: str) -> str:
        """Write the view's image and append it to ``poses.json``; returns the image file name."""
        name = f"{self.count:03d}.png"
        image = view.image if view.image.ndim == 2 else cv2.cvtColor(view.image, cv2.COLOR_RGB2BGR)
        if not cv2.imwrite(str(self.folder / name), image):
            raise OSError(f"could not write {self.folder / name}")
        entry = {"image": name, "arm": view.arm, "state": view.state.tolist(), "pose": pose}
        if view.command is not None:
            entry["command"] = view.command.tolist()
        self.doc["views"].append(entry)
        self.doc["image_size"] = list(view.image_size)
        _write_json(self.folder / POSES_FILE, self.doc)
        return name


def plan_text(plan: CollectionPlan, rig: RigRobot, settings: MoveSettings, start: npt.ArrayLike) -> list[str]:
    """What the operator is shown before the robot moves: per arm the count, workspace box, speed and time."""
    lines = []
    kin = rig.rig.kinematics
    for arm in plan.arms:
        names = plan.pose_names(arm)
        todo = [np.asarray(c) for c, n in zip(arm.commands, names, strict=True) if n not in plan.outcome]
        if not todo:
            continue
        mount = getattr(kin, arm.arm)
        from pilworld.kinematics.fk import fk

        joints = ARM_LAYOUT[arm.arm][0]
        tcp = np.array([(mount.T_rig_base @ fk(c[joints], mount.dh) @ mount.T_flange_tcp)[:3, 3] for c in todo])
        lo, hi = tcp.min(axis=0) * 1000, tcp.max(axis=0) * 1000
        seconds, here = 0.0, np.asarray(start, dtype=np.float64)
        for c in todo:
            seconds += move_duration(here, c, settings) + settings.settle_s + 0.3
            here = c
        earlier = f" ({len(names) - len(todo)} done earlier)" if len(todo) < len(names) else ""
        lines.append(
            f"{arm.arm} arm: {len(todo)} poses{earlier}; TCP within x {lo[0]:.0f}..{hi[0]:.0f}, "
            f"y {lo[1]:.0f}..{hi[1]:.0f}, z {lo[2]:.0f}..{hi[2]:.0f} mm (rig frame); joints at most "
            f"{settings.speed:.2f} rad/s; about {seconds / 60:.1f} min"
        )
        if arm.summary:
            lines.append(f"  {arm.summary}")
    return lines


@dataclass
class CollectionReport:
    recorded: int = 0
    skipped: dict[str, str] = field(default_factory=dict)
    seconds: float = 0.0


def collect_on_rig(
    rig: RigRobot,
    plan: CollectionPlan,
    store: ViewStore,
    settings: MoveSettings,
    *,
    before_arm: Callable[[str], None] = lambda arm: None,
    log: Callable[[str], None] = print,
    camera: str = HEAD_VIEW,
) -> CollectionReport:
    """Visit every pose of ``plan`` not yet done, recording a view at each (see the module docstring).

    ``before_arm(arm)`` is called before an arm's first pose (the board moves to that arm's gripper).
    Raises :class:`CollectionStoppedError` when a device fault or Ctrl-C stops the collection.
    """
    robot = rig.robot
    spec = robot.spec
    rate = float(spec.control_rate_hz)
    report = CollectionReport()
    t0 = time.monotonic()
    hold = np.asarray(plan.hold, dtype=np.float64)
    check = SafetyFilter(spec)  # refusals before moving: the target alone, nothing is stopped
    # A view on disk counts as recorded even if the stop came between writing it and updating plan.json.
    for entry in store.doc["views"]:
        if entry.get("pose"):
            plan.outcome.setdefault(str(entry["pose"]), f"recorded: {entry['image']}")
    try:
        for arm in plan.arms:
            names = plan.pose_names(arm)
            if all(n in plan.outcome for n in names):
                continue
            before_arm(arm.arm)
            here = np.asarray(robot.state(), dtype=np.float64)
            for name, command in zip(names, arm.commands, strict=True):
                if name in plan.outcome:
                    continue
                goal = np.asarray(command, dtype=np.float64)
                # The grips keep what they measure now (the board is clamped; never open a gripper holding it).
                for side in ARM_LAYOUT:
                    goal[ARM_LAYOUT[side][1]] = here[ARM_LAYOUT[side][1]]
                try:
                    check.reset(goal)
                    check(goal)
                except SafetyViolationError as exc:
                    _skip(plan, store, report, name, f"refused by the safety filter: {exc}", log)
                    continue
                waypoints = [goal]
                problem = path_problem(rig.rig.kinematics, here, goal, settings)
                if problem is not None:
                    via = hold.copy()
                    for side in ARM_LAYOUT:
                        via[ARM_LAYOUT[side][1]] = here[ARM_LAYOUT[side][1]]
                    detour = path_problem(rig.rig.kinematics, here, via, settings) or path_problem(
                        rig.rig.kinematics, via, goal, settings
                    )
                    if detour is not None:
                        _skip(plan, store, report, name, f"no safe path: {problem}", log)
                        continue
                    waypoints = [via, goal]
                safety = SafetyFilter(spec, clock=robot.clock, on_violation=robot.stop, device="calibration move")
                safety.reset(here)
                try:
                    for w in waypoints:
                        here = paced_move(robot, safety, here, w, settings, rate_hz=rate)
                except SafetyViolationError as exc:
                    here = np.asarray(robot.state(), dtype=np.float64)
                    _skip(plan, store, report, name, f"refused by the safety filter during the move: {exc}", log)
                    continue
                settled_at = time.monotonic()
                image = rig.grab(camera, after=settled_at)
                state = np.asarray(robot.state(), dtype=np.float64)
                view = RecordedView(name=name, arm=arm.arm, image=image, state=state, command=goal)
                file = store.add(view, name)
                plan.outcome[name] = f"recorded: {file}"
                plan.save(store.folder)
                report.recorded += 1
                off = float(np.max(np.abs(state[ARM_LAYOUT[arm.arm][0]] - goal[ARM_LAYOUT[arm.arm][0]])))
                log(f"{name}: recorded {file} ({store.count} views; settled {np.degrees(off):.2f}° from the target)")
                here = state
            here = _back_to_hold(rig, hold, here, settings, rate, arm.arm, log)
    except RobotError as exc:
        raise CollectionStoppedError(_stopped(str(exc), store, plan)) from None
    except KeyboardInterrupt:
        try:
            robot.stop()
        finally:
            raise CollectionStoppedError(_stopped("interrupted (Ctrl-C)", store, plan)) from None
    report.seconds = time.monotonic() - t0
    return report


def _back_to_hold(
    rig: RigRobot,
    hold: FloatArray,
    here: FloatArray,
    settings: MoveSettings,
    rate: float,
    arm: str,
    log: Callable[[str], None],
) -> FloatArray:
    """Bring ``arm`` back to the pose the collection started from (the next arm's plan assumes it there)."""
    goal = here.copy()
    goal[ARM_LAYOUT[arm][0]] = hold[ARM_LAYOUT[arm][0]]
    problem = path_problem(rig.rig.kinematics, here, goal, settings)
    if problem is not None:
        log(f"the {arm} arm stays at its last pose: no safe path back to the start ({problem})")
        return here
    robot = rig.robot
    safety = SafetyFilter(robot.spec, clock=robot.clock, on_violation=robot.stop, device="calibration move")
    safety.reset(here)
    log(f"the {arm} arm returns to the start pose")
    return paced_move(robot, safety, here, goal, settings, rate_hz=rate)


def _skip(
    plan: CollectionPlan, store: ViewStore, report: CollectionReport, name: str, why: str, log: Callable[[str], None]
) -> None:
    plan.outcome[name] = f"skipped: {why}"
    plan.save(store.folder)
    report.skipped[name] = why
    log(f"{name}: skipped — {why}")


def _stopped(what: str, store: ViewStore, plan: CollectionPlan) -> str:
    return (
        f"collection stopped: {what}; the arms are stopped; {store.count} view(s) kept in {store.folder}, "
        f"{plan.remaining()} pose(s) to go; rerun the same command with --resume to continue"
    )
