"""Example action chunks for the simulated rig (arms mounted as in ``configs/rig/sim_dual_ur5e.yaml``).

Used by the demo (a reach-and-grasp chunk to render) and by ``pilworld bench control-video`` (random
smooth chunks around a home pose, so the benchmark draws what a policy would produce: markers mostly
in view, some leaving it). Joint vectors follow the 14-d layout ``[L j1..j6, L grip, R j1..j6, R grip]``.

Run ``python -m pilworld.control_video.examples OUT.npy`` to write the reach-and-grasp chunk.
"""

from __future__ import annotations

import argparse
import math
from pathlib import Path

import numpy as np
from numpy.typing import NDArray


def _arm(pan: float, shoulder: float, elbow: float) -> list[float]:
    # Wrist 1 chosen so shoulder + elbow + wrist1 = −π/2: the tool z axis points straight down.
    return [pan, shoulder, elbow, -math.pi / 2 - (shoulder + elbow), -math.pi / 2, 0.0]


# Both grippers open, 10 cm above the table at x = 0.10 m, 27 cm either side of the centre line,
# pointing down. The pans differ because a UR arm is not mirror-symmetric (its shoulder offset d4).
HOME_Q14 = np.array([*_arm(-0.3, -1.3, 1.9), 1.0, *_arm(-0.19, -1.3, 1.9), 1.0], dtype=np.float32)


def _smoothstep(n: int) -> NDArray[np.float64]:
    t = np.linspace(0.0, 1.0, n)
    return t * t * (3.0 - 2.0 * t)


def reach_and_grasp_chunk(horizon: int = 50) -> NDArray[np.float32]:
    """A (horizon, 14) chunk: the left arm descends, closes its gripper and lifts; the right arm sweeps
    towards the centre while half-closing. Deterministic."""
    if horizon < 10:
        raise ValueError(f"horizon: expected at least 10 steps, got {horizon}")
    descend = np.array([*_arm(-0.3, -1.05, 1.85), 1.0, *_arm(-0.19, -1.3, 1.9), 1.0], dtype=np.float64)
    grasp = descend.copy()
    grasp[6] = 0.0
    lift = np.array([*_arm(-0.15, -1.45, 1.9), 0.0, *_arm(0.1, -1.3, 1.9), 0.5], dtype=np.float64)
    n1, n2 = int(horizon * 0.4), int(horizon * 0.2)
    n3 = horizon - n1 - n2
    home = HOME_Q14.astype(np.float64)
    seg1 = home + _smoothstep(n1)[:, None] * (descend - home)
    seg2 = descend + _smoothstep(n2)[:, None] * (grasp - descend)
    seg3 = grasp + _smoothstep(n3)[:, None] * (lift - grasp)
    return np.concatenate([seg1, seg2, seg3]).astype(np.float32)


def random_chunks(
    n: int, horizon: int = 50, *, seed: int = 0, joint_range: float = 0.35, waypoints: int = 4
) -> NDArray[np.float32]:
    """(n, horizon, 14) smooth random chunks around :data:`HOME_Q14`.

    Each chunk interpolates (smoothstep) between ``waypoints`` random joint offsets of up to
    ``joint_range`` rad and random grip values, the kind of motion a policy chunk contains.
    """
    if n < 1 or horizon < 2 or waypoints < 2:
        raise ValueError(f"random_chunks: need n ≥ 1, horizon ≥ 2, waypoints ≥ 2; got {n}, {horizon}, {waypoints}")
    rng = np.random.default_rng(seed)
    keys = HOME_Q14[None, None, :] + rng.uniform(-joint_range, joint_range, size=(n, waypoints, 14))
    keys[..., [6, 13]] = rng.uniform(0.0, 1.0, size=(n, waypoints, 2))
    pos = np.linspace(0.0, waypoints - 1, horizon)
    lo = np.minimum(pos.astype(int), waypoints - 2)
    w = pos - lo
    w = (w * w * (3.0 - 2.0 * w))[None, :, None]
    chunks: NDArray[np.float64] = keys[:, lo] * (1.0 - w) + keys[:, lo + 1] * w
    return chunks.astype(np.float32)


def starting_at(chunk: NDArray[np.floating], state: NDArray[np.floating]) -> NDArray[np.float32]:
    """``chunk`` (..., H, 14) bent to begin at ``state`` (14,): the offset of its first row fades out linearly.

    A chunk written for one start pose then continues from another one smoothly, as a policy's would.
    """
    c = np.asarray(chunk, dtype=np.float64)
    lead = np.linspace(1.0, 0.0, c.shape[-2])[:, None]
    return (c + (np.asarray(state, dtype=np.float64) - c[..., :1, :]) * lead).astype(np.float32)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description="Write the example reach-and-grasp chunk as .npy")
    parser.add_argument("out", type=Path)
    parser.add_argument("--horizon", type=int, default=50)
    parser.add_argument(
        "--from-sim-start",
        action="store_true",
        help="begin at the simulated rig's start pose (where every simulated subtask starts)",
    )
    args = parser.parse_args(argv)
    args.out.parent.mkdir(parents=True, exist_ok=True)
    chunk = reach_and_grasp_chunk(args.horizon)
    if args.from_sim_start:
        from simrig.poses import HOME_Q14 as SIM_START

        chunk = starting_at(chunk, SIM_START)
    np.save(args.out, chunk)
    print(f"wrote {args.out}")
    return 0


if __name__ == "__main__":  # pragma: no cover
    raise SystemExit(main())
