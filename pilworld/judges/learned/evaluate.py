"""How well a learned judge agrees with a label source on episodes it did not see (``pilworld judge evaluate``).

Agreement is measured on the episodes the judge answers; abstentions are counted apart (they go to
people). ``degrade`` passes every frame the judge reads through what imagined frames suffer first —
blur, a coarser image, sensor noise (:data:`DEGRADATIONS`) or any callable — to show whether the judge
punishes a faithful but imperfect rendering (docs/judges.md, "Fairness").
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import replace
from pathlib import Path
from typing import Any

import cv2
import numpy as np
from numpy.typing import NDArray
from tqdm import tqdm

from pilworld.config.rig import RigConfig
from pilworld.judges.learned.examples import Example, stored_example
from pilworld.judges.learned.judge import LearnedSuccessJudge
from pilworld.judges.learned.labels import labelled_episodes, open_store

Degrade = Callable[[NDArray[np.uint8]], NDArray[np.uint8]]  # one (6, S, S) first/last frame stack


def _per_frame(fn: Callable[[NDArray[np.uint8]], NDArray[np.uint8]]) -> Degrade:
    def apply(stack: NDArray[np.uint8]) -> NDArray[np.uint8]:
        frames = [stack[i : i + 3].transpose(1, 2, 0) for i in (0, 3)]
        return np.concatenate([fn(np.ascontiguousarray(f)).transpose(2, 0, 1) for f in frames])

    return apply


def _blur(img: NDArray[np.uint8]) -> NDArray[np.uint8]:
    return np.asarray(cv2.GaussianBlur(img, (0, 0), 1.0), np.uint8)


def _coarse(img: NDArray[np.uint8]) -> NDArray[np.uint8]:
    h, w = img.shape[:2]
    small = cv2.resize(img, (w // 2, h // 2), interpolation=cv2.INTER_AREA)
    return np.asarray(cv2.resize(small, (w, h), interpolation=cv2.INTER_LINEAR), np.uint8)


def _noise(img: NDArray[np.uint8]) -> NDArray[np.uint8]:
    rng = np.random.default_rng(int(img.sum()) % (2**32))
    return np.clip(img.astype(np.float32) + rng.normal(0, 6, img.shape), 0, 255).astype(np.uint8)


DEGRADATIONS: dict[str, Degrade] = {
    "blur": _per_frame(_blur),
    "coarse": _per_frame(_coarse),
    "noise": _per_frame(_noise),
}


def degraded(example: Example, degrade: Degrade) -> Example:
    E, V = example.frames.shape[:2]
    frames = np.stack([np.stack([degrade(example.frames[e, v]) for v in range(V)]) for e in range(E)])
    return replace(example, frames=frames)


def evaluate(
    judge: LearnedSuccessJudge,
    roots: Sequence[Path],
    source: str,
    *,
    degrade: Degrade | None = None,
    progress: bool = True,
    rig: RigConfig | None = None,
) -> dict[str, Any]:
    """Agreement, abstentions and the confusion matrix of ``judge`` against ``source`` labels on ``roots``."""
    labelled = labelled_episodes(roots, source)
    stores = {root: open_store(root) for root in dict.fromkeys(lab.root for lab in labelled)}
    for root, store in stores.items():
        judge.folder.spec.check(store.spec.views, store.spec.state_dim, f"--data {root}")
    rows: list[tuple[str, bool, bool | None, float]] = []
    for lab in tqdm(labelled, desc="judging", unit="episode", disable=not progress):
        store = stores[lab.root]
        example = stored_example(store, lab.index, judge.folder.spec, rig)
        if degrade is not None:
            example = degraded(example, degrade)
        pred = judge.predict_example(example)
        rows.append(
            (example.instruction, lab.success, (pred.probability >= 0.5) if pred.confident else None, pred.probability)
        )
    out = agreement(rows)
    out["per_instruction"] = {key: agreement([r for r in rows if r[0] == key]) for key in sorted({r[0] for r in rows})}
    return out


def agreement(rows: Sequence[tuple[str, bool, bool | None, float]]) -> dict[str, Any]:
    answered = [(truth, said) for _, truth, said, _ in rows if said is not None]
    right = sum(truth == said for truth, said in answered)
    return {
        "episodes": len(rows),
        "answered": len(answered),
        "abstained": len(rows) - len(answered),
        "abstain_share": round((len(rows) - len(answered)) / len(rows), 4) if rows else None,
        "agreement": round(right / len(answered), 4) if answered else None,
        "confusion": {
            "true_pos": sum(t and s for t, s in answered),
            "false_pos": sum((not t) and s for t, s in answered),
            "true_neg": sum((not t) and (not s) for t, s in answered),
            "false_neg": sum(t and (not s) for t, s in answered),
        },
        "successes": sum(truth for _, truth, _, _ in rows),
    }
