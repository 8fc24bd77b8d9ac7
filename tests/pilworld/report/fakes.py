"""Stand-ins for what other steps write into a paired run folder: image-judge verdicts and metrics.json."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

from pilworld.data.outcomes import Outcome, record_outcomes
from pilworld.data.reader import EpisodeStore

FAKE_JUDGE = "vision_fake"


def judge_run(root: Path) -> dict[str, int | None]:
    """A fake image-only judge's verdict on every episode; every other imagined one hallucinates.

    Returns pair id → the imagined branch's first hallucination frame (None if none).
    """
    store = EpisodeStore(root)
    marks: dict[str, int | None] = {}
    verdicts = []
    for i, row in enumerate(store.episodes):
        pair = json.loads(row["extra"])["pair"]
        length = int(row["length"])
        t_h = None
        if row["origin"] == "imagined" and len(marks) % 2 == 0:
            t_h = min(length - 1, 7 + len(marks))
        if row["origin"] == "imagined":
            marks[pair] = t_h
        verdicts.append(Outcome(i, FAKE_JUDGE, "vision", success=t_h is None, num_frames=length,
                                first_hallucination_frame=t_h))  # fmt: skip
    record_outcomes(root, verdicts, num_episodes=store.num_episodes)
    return marks


def fake_metrics(checkpoints: list[str], task: str = "sort_cubes", frames: int = 15) -> dict[str, Any]:
    """A metrics.json in the layout pilworld.metrics writes (values made up, some keys left out)."""
    settings = [
        {"task": task, "checkpoint": c, "sr_real": round(0.2 + 0.3 * i, 3), "sr_imag": round(0.1 + 0.35 * i, 3), "n": 3}
        for i, c in enumerate(checkpoints)
    ]
    views = ("cam_high", "cam_left_wrist", "cam_right_wrist")
    return {
        "tasks": {
            task: {
                "sr_real": 0.5,
                "sr_imag": 0.45,
                "abs_delta_sr": 0.05,
                "hfr": 0.875,
                "ci95": {"sr_real": [0.25, 0.75], "sr_imag": [0.2, 0.7], "hfr": {"lo": 0.7, "hi": 0.95}},
            }
        },
        "settings": settings,
        "overall": {
            "sr_real": 0.5,
            "sr_imag": 0.45,
            "abs_delta_sr": 0.05,
            "hfr": 0.875,
            "pearson": 0.987,
            "spearman": 1.0,
            "ci95": {"pearson": [0.5, 1.0]},
        },  # no mmrv: the report shows "—"
        "single_step": {
            "per_view": {
                v: {
                    "psnr": [30.0 - 0.4 * k - j for k in range(frames)],
                    "ssim": [0.95 - 0.01 * k for k in range(frames)],
                }
                for j, v in enumerate(views)
            }
        },
    }


def write_fake_metrics(root: Path, checkpoints: list[str]) -> dict[str, Any]:
    metrics = fake_metrics(checkpoints)
    (root / "metrics.json").write_text(json.dumps(metrics, indent=2))
    return metrics
