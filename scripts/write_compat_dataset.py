"""Write a dataset with PiL-World's episode store plus the arrays LeRobot should read back from it.

Used by scripts/check_lerobot_compat.sh: the dataset goes to OUT/, the expected arrays (global
frame order, the layout lerobot_compat_check.py --compare-npz reads) to OUT.npz.
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

from pilworld.bench.data import synthetic_episode
from pilworld.data.spec import DatasetSpec
from pilworld.data.writer import EpisodeWriter
from pilworld.types import DEFAULT_VIEWS


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("out", type=Path)
    parser.add_argument("--video-mode", default="lossless", choices=["h264", "lossless", "av1"])
    parser.add_argument("--size", type=int, default=64)
    args = parser.parse_args()
    lengths = (20, 25, 30)
    episodes = [synthetic_episode(n, seed, args.size) for seed, n in enumerate(lengths)]
    tasks = ["sort the cubes by size.", "pick up the bowls and stack them one by one."]
    spec = DatasetSpec(views={v: (args.size, args.size) for v in DEFAULT_VIEWS}, video_mode=args.video_mode)
    expected: dict[str, list[np.ndarray]] = {"state": [], "action": [], "episode_index": [], "task": []}
    with EpisodeWriter(args.out, spec) as writer:
        for e, ep in enumerate(episodes):
            ep = type(ep)(**{**ep.__dict__, "task": tasks[e % 2], "origin": ("real", "imagined")[e % 2]})
            writer.append(ep)
            expected["state"].append(ep.state)
            expected["action"].append(ep.action)
            expected["episode_index"].append(np.full(ep.length, e))
            expected["task"].append(np.array([ep.task] * ep.length))
            for v in DEFAULT_VIEWS:
                expected.setdefault(f"images.{v}", []).append(ep.images[v])
    np.savez(args.out.with_suffix(".npz"), **{k: np.concatenate(v) for k, v in expected.items()})
    print(f"wrote {args.out} and {args.out.with_suffix('.npz')}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
