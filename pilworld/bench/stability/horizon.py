"""Probes 1 and 2's figures from a judged R-round paired run: HFR per horizon, head-view PSNR per round."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from pilworld.bench.stability.metrics import frame_psnr
from pilworld.bench.stability.settings import HEAD, HORIZONS


def horizon_sweep(run: Path, rounds: int, frames_per_round: int) -> dict[str, Any]:
    """HFR at each horizon and per-round head-view PSNR from a judged R-round paired run."""
    from pilworld.data.pairs import load_pairs
    from pilworld.data.reader import EpisodeStore
    from pilworld.metrics.success import CHECKER_KIND

    store = EpisodeStore(run)
    paired = load_pairs(run, store)
    rows = []
    for h in (h for h in HORIZONS if h <= rounds):
        t_r = 1 + h * frames_per_round
        values = []
        for pair in paired.pairs:
            for o in paired.outcomes(pair.imagined):
                if o.judge_kind == CHECKER_KIND:
                    continue
                t_h = o.num_frames if o.first_hallucination_frame is None else o.first_hallucination_frame
                values.append(min(t_h, t_r) / t_r)
        rows.append({"rounds": h, "frames": t_r, "hfr": float(np.mean(values)) if values else None, "n": len(values)})
    per_round: list[dict[str, Any]] = []
    sums: dict[int, list[tuple[float, float]]] = {}
    for pair in paired.pairs:
        imag = store.frames(pair.imagined, HEAD)
        real = store.frames(pair.real, HEAD)
        n = min(len(imag), len(real))
        for r in range(1, rounds + 1):
            k = r * frames_per_round
            if k < n:
                sums.setdefault(r, []).append((frame_psnr(imag[k], real[k]), frame_psnr(real[0], real[k])))
    for r, vals in sorted(sums.items()):
        per_round.append(
            {
                "round": r,
                "psnr_head": float(np.mean([v[0] for v in vals])),
                "psnr_head_frozen": float(np.mean([v[1] for v in vals])),
                "n": len(vals),
            }
        )
    return {"rows": rows, "per_round": per_round, "pairs": len(paired.pairs), "run": str(run)}
