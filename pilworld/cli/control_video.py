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
from pilworld.io.video import write_frames
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
    p.add_argument("--fps", type=float, help="video frame rate (default: control rate / stride, i.e. real time)")
    p.add_argument("--json", action="store_true", help="print a JSON summary as the last line")
    p.set_defaults(handler=run)


def parse_size(text: str) -> tuple[int, int]:
    try:
        w, h = (int(v) for v in text.lower().split("x"))
    except ValueError:
        raise ValueError(f"--size: expected WIDTHxHEIGHT such as 128x128, got {text!r}") from None
    if not (0 < w <= 8192 and 0 < h <= 8192):
        raise ValueError(f"--size: width and height must be in 1..8192, got {text!r}")
    return w, h


def run(args: argparse.Namespace) -> int:
    rig = RigConfig.load(args.rig)
    if args.size:
        w, h = parse_size(args.size)
        rig = RigConfig.model_validate({**rig.model_dump(), "image_size": {"width": w, "height": h}})
    spec = ChunkSpec(horizon=max(50, args.frames * args.stride), frames=args.frames, stride=args.stride)
    gamma = ControlVideo.from_rig(rig, spec, ControlVideoStyle(trace_length=args.trace_length))

    actions = load_npy(args.actions, what="--actions")
    if not (actions.ndim in (2, 3) and actions.shape[-1] == STATE_DIM):
        raise ValueError(
            f"--actions: expected shape (H, {STATE_DIM}) or (R, H, {STATE_DIM}), "
            f"got {actions.shape} from {args.actions}"
        )
    if actions.ndim == 2:
        actions = actions[None]
    if actions.shape[1] < spec.executed_steps:
        raise ValueError(
            f"--actions: chunk has {actions.shape[1]} steps but K·Δ = {spec.frames}·{spec.stride} = "
            f"{spec.executed_steps} are needed ({args.actions})"
        )
    previous = None
    if args.previous_state is not None:
        previous = load_npy(args.previous_state, what="--previous-state").reshape(-1)
        if previous.shape != (STATE_DIM,):
            raise ValueError(f"--previous-state: expected {STATE_DIM} values, got shape {previous.shape}")

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
