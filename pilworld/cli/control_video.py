"""``pilworld control-video``: render Γ for recorded action chunks into an MP4 or a PNG contact sheet."""

from __future__ import annotations

import argparse
import json
from pathlib import Path
from typing import Any

import numpy as np

from pilworld.cli.arrays import load_npy
from pilworld.config.rig import RigConfig
from pilworld.control_video import ControlVideo, ControlVideoStyle
from pilworld.control_video.robot_render import BACKENDS
from pilworld.control_video.styles import STYLES, Style
from pilworld.io.video import write_frames
from pilworld.options.parse import parse_size
from pilworld.types import STATE_DIM, ChunkSpec


def register(sub: Any) -> None:
    p: argparse.ArgumentParser = sub.add_parser(
        "control-video",
        help="render the head-view control video Γ of action chunks",
        description=(
            "Render Γ (paper §3.2): the K stride-aligned actions of each chunk → gripper points by forward "
            "kinematics → head-camera projection → one marker per gripper (size = opening) with fading traces. "
            f"ACTIONS is a .npy of one chunk (H, {STATE_DIM}) or of consecutive rounds (R, H, {STATE_DIM}); "
            "rounds are chained, each starting from the previous round's last stride-aligned action."
        ),
    )
    p.add_argument("--rig", required=True, type=Path, help="rig config YAML (e.g. configs/rig/sim_dual_ur5e.yaml)")
    p.add_argument(
        "--actions",
        required=True,
        type=Path,
        help=f"chunk(s) .npy, shape (H, {STATE_DIM}) or (R, H, {STATE_DIM})",
    )
    p.add_argument("--out", required=True, type=Path, help="output .mp4 (video) or .png (contact sheet)")
    p.add_argument(
        "--previous-state",
        type=Path,
        help=f"state before the first chunk, .npy ({STATE_DIM},), draws its trace",
    )
    p.add_argument("--frames", "-K", type=int, default=15, help="K, frames per chunk (default 15)")
    p.add_argument("--stride", type=int, default=3, help="Δ, control steps between frames (default 3)")
    p.add_argument("--size", type=str, help="WIDTHxHEIGHT, overrides the rig's image size")
    p.add_argument(
        "--trace-length", type=int, default=ControlVideoStyle.trace_length, help="trace segments (default 3)"
    )
    p.add_argument(
        "--style",
        default="markers",
        help=f"what to draw: {', '.join(STYLES)} (default markers: the paper's Γ, head view only; the others draw "
        "every view side by side, docs/control_video.md)",
    )
    p.add_argument("--backend", choices=BACKENDS, default="analytic", help="robot renderer of the render styles")
    p.add_argument(
        "--task",
        help="prior styles on the simulated rig: take the current frames and state from this task's start",
    )
    p.add_argument("--seed", type=int, default=1_000_000, help="layout seed of --task's start (default 1000000)")
    p.add_argument("--subtask", type=int, default=0, help="subtask of --task's start (default 0)")
    p.add_argument(
        "--current-images",
        type=Path,
        help="prior styles: folder with one PNG per view (cam_high.png, …), the frames the chunk starts from",
    )
    p.add_argument("--current-state", type=Path, help=f"prior styles: .npy ({STATE_DIM},), the state at those frames")
    p.add_argument("--fps", type=float, help="video frame rate (default: control rate / stride, i.e. real time)")
    p.add_argument("--json", action="store_true", help="print a JSON summary as the last line")
    p.set_defaults(handler=run)


def run(args: argparse.Namespace) -> int:
    from pilworld.io.run_folder import check_out_file

    check_out_file(args.out, "--out", suffixes=(".mp4", ".png"))  # before any work: a name it can write
    style = Style.parse(args.style)
    rig = RigConfig.load(args.rig)
    if args.size:
        w, h = parse_size(args.size)
        rig = RigConfig.model_validate({**rig.model_dump(), "image_size": {"width": w, "height": h}})
    spec = ChunkSpec(horizon=max(50, args.frames * args.stride), frames=args.frames, stride=args.stride)
    if style.name != "markers":
        return _run_gamma_plus(args, rig, spec, style)
    gamma = ControlVideo.from_rig(rig, spec, ControlVideoStyle(trace_length=args.trace_length))

    actions = _load_chunks(args.actions, spec)
    previous = _load_previous(args)
    limits = rig.robot_spec()
    check_joint_limits(actions, limits, "--actions", args.actions)
    if previous is not None:
        check_joint_limits(previous, limits, "--previous-state", args.previous_state)

    # Rounds chain: round r starts where round r−1's last stride-aligned action left the arms.
    stride_actions = gamma.stride_aligned(actions)
    parts = [gamma(actions[0], previous)[None]]
    if actions.shape[0] > 1:
        parts.append(gamma.render_batch(actions[1:], stride_actions[:-1, -1]))
    video = np.concatenate(parts).reshape(-1, gamma.height, gamma.width, 3)
    fps = args.fps if args.fps is not None else rig.control_rate_hz / args.stride
    out = write_frames(video, args.out, fps=fps, columns=min(args.frames, 5))

    geo = gamma.geometry(stride_actions)
    summary = {
        "out": str(out),
        "rounds": int(actions.shape[0]),
        "frames": int(video.shape[0]),
        "image_size": [gamma.width, gamma.height],
        "fps": fps,
        "markers_visible": int(geo.visible.sum()),
        "markers_drawn": int(geo.marker.sum()),
        "markers_total": int(geo.marker.size),
    }
    print(
        f"wrote {out}: {summary['frames']} frames ({summary['rounds']} round(s) × K={args.frames}) at "
        f"{gamma.width}x{gamma.height}; markers drawn {summary['markers_drawn']}/{summary['markers_total']}"
        f" (centre in image: {summary['markers_visible']})"
    )
    if args.json:
        print(json.dumps(summary))
    return 0


LIMIT_SLACK = 0.05  # rad (or gripper fraction) beyond a joint's limit still drawn: servo overshoot, rounding


def check_joint_limits(values: np.ndarray, spec: Any, what: str, path: Path) -> None:
    """Refuse joint values outside the rig's limits (radians, grippers 0..1): a chunk in degrees or a
    scaled one draws no marker at all, silently."""
    lower = np.asarray(spec.lower) - LIMIT_SLACK
    upper = np.asarray(spec.upper) + LIMIT_SLACK
    bad = np.argwhere((values < lower) | (values > upper))
    if bad.size:
        index = tuple(int(i) for i in bad[0])
        j = index[-1]
        raise ValueError(
            f"{what}: {path}: {spec.joint_names[j]} is {values[index]:.6g} at index {index}, outside the rig's "
            f"limits [{spec.lower[j]:.4g}, {spec.upper[j]:.4g}] ({len(bad)} value(s) out of range; radians, "
            "grippers 0..1)"
        )


def _load_chunks(path: Path, spec: ChunkSpec) -> np.ndarray:
    actions = load_npy(path, what="--actions")
    if not (actions.ndim in (2, 3) and actions.shape[-1] == STATE_DIM):
        raise ValueError(
            f"--actions: expected shape (H, {STATE_DIM}) or (R, H, {STATE_DIM}), got {actions.shape} from {path}"
        )
    if actions.ndim == 2:
        actions = actions[None]
    if actions.shape[1] < spec.executed_steps:
        raise ValueError(
            f"--actions: chunk has {actions.shape[1]} steps but K·Δ = {spec.frames}·{spec.stride} = "
            f"{spec.executed_steps} are needed ({path})"
        )
    return actions.astype(np.float64)


def _load_previous(args: argparse.Namespace) -> np.ndarray | None:
    """``--previous-state`` as a float64 (14,) vector, or None."""
    if args.previous_state is None:
        return None
    previous = load_npy(args.previous_state, what="--previous-state").reshape(-1).astype(np.float64)
    if previous.shape != (STATE_DIM,):
        raise ValueError(f"--previous-state: expected {STATE_DIM} values, got shape {previous.shape}")
    return previous


def _current(args: argparse.Namespace, rig: RigConfig) -> tuple[dict[str, np.ndarray] | None, np.ndarray | None]:
    """The frames and state a chunk starts from: a simulated task start, files, or none."""
    if args.task is not None and args.current_images is not None:
        raise ValueError("--task and --current-images: give one source of the current frames, not both")
    if args.task is not None:
        from simrig.robot import SimRobot

        with SimRobot(rig, args.task) as sim:
            sim.reset(seed=args.seed, subtask=args.subtask, history=0)
            obs = sim.observe()
        return dict(obs.images), np.asarray(obs.state, dtype=np.float64)
    state = None
    if args.current_state is not None:
        state = load_npy(args.current_state, what="--current-state").reshape(-1).astype(np.float64)
        if state.shape != (STATE_DIM,):
            raise ValueError(f"--current-state: expected {STATE_DIM} values, got shape {state.shape}")
    if args.current_images is None:
        return None, state
    import cv2

    images = {}
    for view in rig.cameras:
        path = args.current_images / f"{view}.png"
        img = cv2.imread(str(path), cv2.IMREAD_COLOR)
        if img is None:
            raise ValueError(
                f"--current-images: {path} is missing or not an image (one PNG per view: {list(rig.cameras)})"
            )
        want = (rig.image_size.height, rig.image_size.width)
        if img.shape[:2] != want:
            raise ValueError(
                f"--current-images: {path} is {img.shape[1]}x{img.shape[0]}, the rig's views are {want[1]}x{want[0]}"
            )
        images[view] = np.ascontiguousarray(img[..., ::-1])
    return images, state


def _run_gamma_plus(args: argparse.Namespace, rig: RigConfig, spec: ChunkSpec, style: Style) -> int:
    """Γ⁺ styles: every view of every frame side by side, rounds chained as for Γ."""
    from pilworld.control_video.gamma_plus import GammaPlus

    actions = _load_chunks(args.actions, spec)
    images, state = _current(args, rig)
    previous = _load_previous(args)
    if previous is None:
        previous = state
    if style.prior and (images is None or (state is None and previous is None)):
        raise ValueError(
            f"--style {style.name}: the prior warps the current frames; give --task T (simulated rig) or "
            "--current-images DIR with --current-state FILE.npy"
        )
    gamma = GammaPlus(rig, style, spec=spec, backend=args.backend)
    parts = []
    start = state if state is not None else previous
    for r, chunk in enumerate(actions):
        out = gamma(chunk, previous_state=previous, current_images=images if r == 0 else None, current_state=start)
        parts.append(np.concatenate([out.images[v] for v in out.views], axis=2))  # views side by side
        if style.prior:
            break  # the prior needs the frames at each round's start: only the first round has them
        previous = start = gamma.markers.stride_aligned(chunk)[-1]
    video = np.concatenate(parts)
    fps = args.fps if args.fps is not None else rig.control_rate_hz / args.stride
    out_path = write_frames(video, args.out, fps=fps, columns=min(args.frames, 5))
    summary = {
        "out": str(out_path),
        "style": style.name,
        "rounds": len(parts),
        "frames": int(video.shape[0]),
        "views": list(gamma.views),
        "image_size": [rig.image_size.width, rig.image_size.height],
        "fps": fps,
    }
    note = " (prior styles draw the first round only)" if style.prior and actions.shape[0] > 1 else ""
    print(
        f"wrote {out_path}: {style.name}, {summary['frames']} frames × {len(gamma.views)} views "
        f"({', '.join(gamma.views)}) at {rig.image_size.width}x{rig.image_size.height}{note}"
    )
    if args.json:
        print(json.dumps(summary))
    return 0
