"""``pilworld calibrate intrinsics --live``: intrinsics from a hardware rig's camera (docs/calibration.md).

Connects the rig's camera through its driver (on the fake rig, the simulator holds the board up to it),
keeps the frames that add coverage or tilt (:mod:`pilworld.calibration.live_intrinsics`) with a running
display, saves them to ``--save`` one by one, and solves them as a folder of images would be solved. A
stalled or lost camera ends the collection with one line naming it; the saved views stay, and ``--resume``
continues from them.
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path
from typing import Any

import numpy as np

from calib.board import ChArUcoBoard
from calib.camera_model import CameraModel
from calib.detect import BoardDetector
from hw_drivers.errors import RobotError
from pilworld.calibration.live_intrinsics import LiveTargets, ViewSelector, collect_live, load_views, status_lines
from pilworld.calibration.rig_devices import CollectionStoppedError, hardware_rig, is_fake, open_camera
from pilworld.cli.terminal import StatusBlock, enter_pressed
from pilworld.types import HEAD_VIEW


def default_views_dir(out: Path) -> Path:
    return out.with_name(out.stem + "_views")


def rough_camera(rig_path: Path, name: str, width: int, height: int) -> CameraModel:
    """The rig's own model of camera ``name`` (designed or calibrated), at the frames' size: a first guess."""
    from pilworld.config.rig import RigConfig

    rig = RigConfig.load(rig_path)
    cam = rig.head_camera_model if name == HEAD_VIEW else rig.wrist_camera_model(name)
    return cam.resized(width, height)


def live_truth(rig_path: Path, name: str, solved: CameraModel) -> dict[str, Any] | None:
    """On the fake rig: how far the solved intrinsics are from the simulated camera's (None elsewhere)."""
    from pilworld.config.rig import RigConfig

    rig = RigConfig.load(rig_path)
    if not is_fake(rig) or rig.hardware is None or rig.hardware.fake is None:
        return None
    size = rig.hardware.fake.stream_sizes.get(name)
    if size is None or (size.width, size.height) != (solved.width, solved.height):
        return None
    true = rough_camera(rig_path, name, size.width, size.height)
    f_true = float(true.K[0, 0])
    return {
        "fx_err_pct": 100.0 * (float(solved.K[0, 0]) - f_true) / f_true,
        "fy_err_pct": 100.0 * (float(solved.K[1, 1]) - float(true.K[1, 1])) / float(true.K[1, 1]),
        "principal_point_err_px": [float(solved.K[0, 2] - true.K[0, 2]), float(solved.K[1, 2] - true.K[1, 2])],
        "true_K": true.K.tolist(),
    }


def targets_from(args: argparse.Namespace) -> LiveTargets:
    return LiveTargets(
        coverage=args.coverage,
        views=args.views,
        max_views=args.max_views,
        rms_px=args.rms,
        pp_sigma_px=args.pp_sigma,
        max_seconds=args.max_seconds,
    )


def intrinsics_live(args: argparse.Namespace, solve: Any) -> int:
    """Collect views live, then ``solve(folder, name)`` them (the folder path of ``calibrate intrinsics``)."""
    rig = hardware_rig(args.rig, "--live")
    targets = targets_from(args)
    board = ChArUcoBoard.from_yaml(args.board)
    save: Path = args.save or default_views_dir(args.out)
    if save.exists() and any(save.iterdir()) and not args.resume:
        raise ValueError(f"--save: {save} already holds views; pass --resume to continue from them, or another --save")
    if is_fake(rig) and args.camera in rig.wrist_cameras:  # refused before the fake rig process starts
        raise ValueError(
            f"--camera {args.camera}: on the fake rig the simulated person holds the board up to the head camera "
            f"({HEAD_VIEW}) only; a wrist camera's intrinsics are calibrated live on a real rig"
        )
    detector = BoardDetector(board)
    block = StatusBlock()
    t0 = time.monotonic()
    with open_camera(args.rig, args.camera) as cam:
        image, _ = cam.grab()
        h, w = image.shape[:2]
        print(f"{cam.name}: {w}x{h} frames from {cam.camera.source}")
        selector = ViewSelector((w, h), rough_camera(args.rig, args.camera, w, h).K, targets)
        if args.resume and save.is_dir():
            earlier = load_views(save, detector)
            try:
                selector.restore([det for _, _, det in earlier])
            except ValueError as exc:
                raise ValueError(f"--resume: {save}: {exc}") from None
            print(f"resumed: {len(earlier)} views from {save}")
        if cam.fake is not None:
            # The simulator stands in for the person: it holds the board up, pose after pose.
            cam.fake.board("hand", args.board)
            n = cam.fake.present_board(args.board, count=2 * targets.max_views, seed=args.seed, hold_s=args.hold)
            print(f"fake rig: the simulator holds the board up to {cam.name}, {n} poses of {args.hold} s each")
        else:
            print(
                f"Hold the board ({board.name}) in front of {cam.name}: the whole image, near and far, tilted up to "
                "~50° towards every side; hold it still for a moment at each pose. Press Enter to stop early."
            )
        print(f"targets: {', '.join(selector.missing()) or 'reached'}")
        asked_at = 0.0

        def stop_requested() -> str | None:
            nonlocal asked_at
            if enter_pressed():
                return "stopped by the operator (Enter)"
            # On the fake rig the simulated person stops after its last pose, as a real one presses Enter.
            if cam.fake is not None and time.monotonic() - asked_at > 0.5:
                asked_at = time.monotonic()
                if not cam.fake.presented()["running"]:
                    return "the simulated person has shown every pose"
            return None

        try:
            result = collect_live(
                cam.grab,
                selector,
                detector,
                save,
                stop_requested=stop_requested,
                show=block.show,
                preview=args.preview,
            )
        except (RobotError, KeyboardInterrupt) as exc:
            what = "interrupted (Ctrl-C)" if isinstance(exc, KeyboardInterrupt) else f"{exc}"
            kept = len(list(save.glob("[0-9][0-9][0-9].png")))
            raise CollectionStoppedError(
                f"collection stopped: {what}; {kept} view(s) kept in {save}; rerun with --resume to continue"
            ) from None
    if not block.tty:  # a log has had one line per kept view; the final coverage map once
        block.finish(status_lines(selector, result.seconds, f"{len(result.views)} views kept"))
    print(f"{result.stop}: {len(result.views)} views kept of {result.frames_seen} frames in {result.seconds:.0f} s")
    if len(result.views) < 4:
        raise ValueError(f"--live: only {len(result.views)} views kept ({result.stop}); a calibration needs >= 4")
    camera, report = solve(save, args.camera)
    truth = live_truth(args.rig, args.camera, camera)
    if truth is not None:
        du, dv = truth["principal_point_err_px"]
        print(
            f"vs the simulator's camera: focal length off by {truth['fx_err_pct']:+.3f} % (fx) and "
            f"{truth['fy_err_pct']:+.3f} % (fy); principal point off by ({du:+.2f}, {dv:+.2f}) px at {w}x{h}"
        )
        report["truth"] = truth
    report["live"] = {
        "rig": rig.name,
        "camera": args.camera,
        "views_dir": str(save),
        "views": len(result.views),
        "frames_seen": result.frames_seen,
        "stop": result.stop,
        "seconds": round(time.monotonic() - t0, 1),
        "coverage_at_stop": selector.coverage,
        "running_rms_px": selector.rms_px,
        "principal_point_sigma_px": selector.pp_sigma_px,
        "tilts_deg": [round(t, 1) for t in selector.tilts],
    }
    if args.json:
        print(json.dumps(report))
    return 0


# ---------------------------------------------------------------------- hand-eye and check on a hardware rig


def _confirm(args: argparse.Namespace, lines: list[str], what: str) -> None:
    """Show the plan; move only with ``--yes`` or an operator's "y" at a terminal (else nothing moves)."""
    import sys

    from pilworld.paired.operator import OperatorUnavailableError

    print("plan:")
    for line in lines:
        print(f"  {line}")
    if args.yes:
        return
    if not sys.stdin.isatty():
        raise OperatorUnavailableError(
            f"{what}: the robot did not move: there is no terminal to confirm the plan above at; run the command "
            "at the rig, or pass --yes to confirm it in advance"
        )
    answer = input(f"Move the robot through this plan ({what})? Keep clear of the arms. [y/N] ").strip().lower()
    if answer not in ("y", "yes"):
        from pilworld.paired.operator import OperatorUnavailableError

        raise OperatorUnavailableError(f"{what}: not confirmed; the robot did not move")


def _mount_board(args: argparse.Namespace, session: Any, arm: str, first: bool) -> None:
    """The board to ``arm``'s gripper: the fake rig's simulated person does it; a real operator is asked."""
    import sys

    if session.fake is not None:
        session.fake.board(arm, args.board_file)
        print(f"fake rig: the simulator mounts the board on the {arm} gripper")
        return
    message = (
        f"Clamp the board on the {arm} gripper with the reference bracket (docs/calibration.md), "
        "printed face towards the head camera"
    )
    if sys.stdin.isatty():
        from pilworld.calibration.rig_devices import person_prompt

        person_prompt(message)
    elif not first:
        raise ValueError(f"--arm both: {message.lower()} — that needs an operator at a terminal between the arms")
    else:
        print(f"assuming the board is on the {arm} gripper (--yes without a terminal)")


def collect_views_on_rig(
    args: argparse.Namespace, purpose: str, folder: Path, arms: tuple[str, ...], seed: int, for_calibration: bool
) -> Any:
    """Plan (or resume), confirm and collect board views on a hardware rig into ``folder``; the Recording.

    On the fake rig the folder also records the simulator's truth (the camera pose and the board mounts).
    """
    from calib.board import ChArUcoBoard
    from pilworld.calibration.plan import PlannerSettings, plan_board_poses
    from pilworld.calibration.recording import CAMERA_FILE, POSES_FILE, Recording
    from pilworld.calibration.rig_collection import ArmPlan, CollectionPlan, ViewStore, collect_on_rig, plan_text
    from pilworld.calibration.rig_devices import open_robot
    from pilworld.calibration.rig_motion import MoveSettings
    from simrig.board_mount import BoardMount

    board = ChArUcoBoard.from_yaml(args.board_file)
    settings = MoveSettings(speed=args.speed)
    if args.resume:
        plan = CollectionPlan.load(folder)
        if plan.purpose != purpose:
            raise ValueError(f"--resume: {folder} holds a {plan.purpose} collection, not a {purpose} one")
    elif (folder / POSES_FILE).is_file():
        raise ValueError(f"--save: {folder} already holds recorded views; pass --resume to continue, or another folder")
    with open_robot(args.rig, what=f"calibrate {purpose}") as session:
        rig = session.rig
        image = session.grab(HEAD_VIEW)
        h, w = image.shape[:2]
        camera = rough_camera(args.rig, HEAD_VIEW, w, h)
        if getattr(args, "camera_model", None) is not None:
            given = CameraModel.from_yaml(args.camera_model)
            if (given.width, given.height) != (w, h):
                raise ValueError(
                    f"--camera-model: {args.camera_model} is for {given.width}x{given.height} images, the head camera "
                    f"sends {w}x{h} (calibrate the intrinsics at the camera's full resolution)"
                )
            camera = given.with_pose(camera.T_cam_base)  # its intrinsics, the rig's rough pose for planning
        state = np.asarray(session.robot.state(), dtype=np.float64)
        if not args.resume:
            arm_plans = []
            for arm in arms:
                mount = BoardMount.beside_tcp(board, arm)
                pose_plan = plan_board_poses(
                    rig.kinematics,
                    camera,
                    board,
                    mount.T_tcp_board,
                    arm,
                    state,
                    PlannerSettings(poses=args.poses),
                    seed,
                    for_calibration=for_calibration,
                )
                arm_plans.append(ArmPlan.from_pose_plan(pose_plan, state))
            plan = CollectionPlan(purpose, state.tolist(), arm_plans, settings={"seed": seed, "speed": args.speed})
        _confirm(args, plan_text(plan, session, settings, state), f"calibrate {purpose}")
        extra: dict[str, Any] = {"source": f"hardware rig {rig.name}", "purpose": purpose}
        if session.fake is not None:
            extra["sim_truth"] = {
                "T_cam_base": rig.head_camera_model.T_cam_base.tolist(),
                "T_tcp_board": {a: BoardMount.beside_tcp(board, a).T_tcp_board.tolist() for a in arms},
            }
        store = ViewStore(folder, rig.name, board, extra)
        plan.save(folder)
        if not (folder / CAMERA_FILE).is_file():
            camera.with_pose(np.eye(4)).to_yaml(folder / CAMERA_FILE)  # the intrinsics the views are solved with
        mounted: list[str] = []

        def before_arm(arm: str) -> None:
            _mount_board(args, session, arm, first=not mounted)
            mounted.append(arm)

        report = collect_on_rig(session, plan, store, settings, before_arm=before_arm)
        if report.skipped:
            print(
                f"{len(report.skipped)} pose(s) skipped: "
                + "; ".join(f"{n}: {why}" for n, why in report.skipped.items())
            )
        print(f"{store.count} views in {folder} ({report.recorded} new, {report.seconds:.0f} s)")
    return Recording.load(folder)
