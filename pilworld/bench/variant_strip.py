"""A rollout strip of one pair across variants: the real branch on top, each variant's imagined branch below.

Columns are the start frame and the last frame of every round, so a reader sees where each variant's
imagined rollout departs from the robot's (an object lost, an arm ghosted, a placement that did not
happen). Every variant of ``pilworld bench paired`` ran the same pairs from the same starts (their real
branches are copies), so the rows line up frame for frame.

    python -m pilworld.bench.variant_strip bench_runs/paired-full \\
        --pair sort_cubes/scripted_step_30k/seed6000000/subtask0 --out docs/results/variant-strip.png
"""

from __future__ import annotations

import argparse
from collections.abc import Mapping, Sequence
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from pilworld.data.pairs import load_pairs
from pilworld.data.reader import EpisodeStore

U8 = NDArray[np.uint8]


def round_ends(rounds: NDArray[np.int64]) -> list[int]:
    """Frame indices shown: the start (0) and the last frame of every round."""
    r = np.asarray(rounds)
    if r.size == 0:
        raise ValueError("episode: no frames")
    ends = [int(i) for i in np.flatnonzero(np.r_[r[1:] != r[:-1], True]) if i > 0]
    return [0, *ends]


def _branch(run: Path, pair_id: str, origin: str, view: str) -> tuple[U8, str]:
    """(frames at the round ends (N, H, W, 3), its verdict text) of one branch of ``pair_id`` in ``run``."""
    store = EpisodeStore(run)
    paired = load_pairs(run, store)
    pair = next((p for p in paired.pairs if p.pair_id == pair_id), None)
    if pair is None:
        known = ", ".join(p.pair_id for p in paired.pairs[:3])
        raise ValueError(f"{run}: no complete pair {pair_id!r} (e.g. {known})")
    index = pair.real if origin == "real" else pair.imagined
    episode = store.load(index, views=[view])
    frames = np.asarray(episode.images[view])[round_ends(episode.rounds())]
    votes = [o.success for o in paired.outcomes(index)]
    verdict = "—" if not votes else ("success" if sum(votes) * 2 > len(votes) else "failure")
    return frames, verdict


def variant_strip(
    runs: Mapping[str, str | Path], pair_id: str, out: str | Path, *, view: str = "cam_high", title: str = ""
) -> Path:
    """Write the strip of ``pair_id`` for ``runs`` (variant name → its run folder, the first one's real
    branch on top) as a PNG; returns its path."""
    import matplotlib

    matplotlib.use("Agg")
    from matplotlib import pyplot as plt

    if not runs:
        raise ValueError("runs: expected at least one variant's run folder")
    names = list(runs)
    rows: list[tuple[str, U8]] = []
    real, verdict = _branch(Path(runs[names[0]]), pair_id, "real", view)
    rows.append((f"real ({verdict})", real))
    for name in names:
        frames, verdict = _branch(Path(runs[name]), pair_id, "imagined", view)
        if frames.shape != real.shape:
            raise ValueError(f"variant {name!r}: {frames.shape[0]} strip frames, the real branch has {real.shape[0]}")
        rows.append((f"{name} ({verdict})", frames))
    n_cols = real.shape[0]
    fig, axes = plt.subplots(len(rows), n_cols, figsize=(1.3 * n_cols + 1.6, 1.3 * len(rows)), squeeze=False)
    for r, (label, frames) in enumerate(rows):
        for c in range(n_cols):
            ax = axes[r][c]
            ax.imshow(frames[c], interpolation="nearest")
            ax.set_xticks([])
            ax.set_yticks([])
            if r == 0:
                ax.set_title("start" if c == 0 else f"round {c}", fontsize=8)
            if c == 0:
                ax.set_ylabel(label, rotation=0, ha="right", va="center", fontsize=8)
    fig.suptitle(title or f"{pair_id} ({view})", fontsize=9)
    fig.tight_layout()
    path = Path(out)
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


def runs_of(bench_out: str | Path, variants: Sequence[str] | None = None) -> dict[str, Path]:
    """Variant name → run folder in a ``pilworld bench paired --out`` folder (those with episodes)."""
    root = Path(bench_out)
    found = {p.name: p for p in sorted(root.iterdir()) if (p / "meta" / "info.json").is_file()} if root.is_dir() else {}
    if not found:
        raise ValueError(f"{root}: no variant run folders (expected {root}/<variant>/meta/info.json)")
    if variants:
        missing = [v for v in variants if v not in found]
        if missing:
            raise ValueError(f"{root}: no run folder for {missing} (found {', '.join(found)})")
        return {v: found[v] for v in variants}
    return found


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="python -m pilworld.bench.variant_strip", description=__doc__.split("\n")[0])
    ap.add_argument("bench_out", type=Path, help="a pilworld bench paired --out folder")
    ap.add_argument("--pair", required=True, help="pair id, e.g. sort_cubes/scripted_step_30k/seed6000000/subtask0")
    ap.add_argument("--variants", default="", help="comma-separated variant names, in row order (default: all)")
    ap.add_argument("--view", default="cam_high")
    ap.add_argument("--out", type=Path, required=True, help="PNG to write")
    args = ap.parse_args(argv)
    chosen = [v for v in args.variants.split(",") if v.strip()] or None
    try:
        path = variant_strip(runs_of(args.bench_out, chosen), args.pair, args.out, view=args.view)
    except ValueError as e:
        print(f"error: {e}")
        return 2
    print(f"wrote {path}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
