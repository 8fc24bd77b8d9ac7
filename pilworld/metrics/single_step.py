"""Single-step image error of a paired run: round 0 of the imagined branch against round 0 of the real one.

Both branches of a pair start from the same stored observation and query the same policy with the
same seed, so round 0 feeds the world model and the robot the same chunk: frames 1..K of the imagined
branch are the world model's single-step prediction for those actions, and frames 1..K of the real
branch are what happened (paper appendix "Single-step LPIPS": K future frames compared with the real
frames at stride Δ; here with the policy's actions rather than a recorded demonstration's).

The premise is checked, not assumed. Paired runs store a digest of each branch's first policy chunk
(``extra.chunk0``): the pair is used when the digests are equal (the same chunk went to the robot and to
the world model, both through the same safety filter; the robot's own final clamp can still differ by
its tracking lag, reported as ``max_abs_action_diff``). Without digests (older runs) the stored
stride-aligned actions of round 0 (rows 0..K−1) must agree within ``action_atol``. Unusable pairs are
skipped and listed.

Scores come from :mod:`pilworld.world_model.metrics` (PSNR, SSIM, the pooled PSNR = PSNR of the mean
MSE, the fraction of bit-exact frames, LPIPS when its weights are on disk), per view and per future
frame index 1..K, with the frozen baseline (the start frame copied K times) beside them, as in
``pilworld bench world-model``.
"""

from __future__ import annotations

import json
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np
import torch
from numpy.typing import NDArray

from pilworld.data.pairs import Pair
from pilworld.data.reader import EpisodeStore, list_column
from pilworld.data.spec import ACTION_KEY
from pilworld.world_model.metrics import LpipsFn, SingleStepScores, load_lpips

DEFAULT_ACTION_ATOL = 1e-5  # rad; float32 storage round-trips exactly, so this only absorbs noise

PROTOCOL = (
    "frames 1..K of round 0, imagined vs real, from the shared start frame and the same policy chunk; "
    "pairs whose first policy chunks differ are skipped"
)


def _round0(store: EpisodeStore, index: int) -> tuple[int, NDArray[np.float32]]:
    """(K, the K stride-aligned actions of round 0) of one episode."""
    table = store.frame_table(index)
    actions = list_column(table, ACTION_KEY, store.spec.action_dim)
    if "round_index" in table.column_names:
        rounds = np.asarray(table.column("round_index").to_numpy(zero_copy_only=False), dtype=np.int64)
    else:
        rounds = np.zeros(len(actions), dtype=np.int64)
    K = int((rounds == 0).sum()) - 1  # frame 0 is the start; frames 1..K were observed in round 0
    return K, actions[: max(K, 0)]


def _clip(frames: dict[str, NDArray[np.uint8]], views: Sequence[str]) -> torch.Tensor:
    """uint8 [1, V, K, 3, H, W] from view → (K, H, W, 3)."""
    stacked = np.stack([frames[v] for v in views])  # [V, K, H, W, 3]
    return torch.from_numpy(np.ascontiguousarray(stacked.transpose(0, 1, 4, 2, 3)))[None]


def _chunk0(store: EpisodeStore, index: int) -> str | None:
    raw = store.episodes[index].get("extra")
    return str(json.loads(raw)["chunk0"]) if raw and "chunk0" in json.loads(raw) else None


def _check_pair(store: EpisodeStore, pair: Pair, atol: float) -> tuple[int, dict[str, Any] | None]:
    """(K, None) when the pair is usable, else (K, the reason it is skipped)."""
    k_imag, a_imag = _round0(store, pair.imagined)
    k_real, a_real = _round0(store, pair.real)
    if k_imag != k_real or k_imag < 1:
        return k_imag, {"pair": pair.pair_id, "reason": f"round 0 has K={k_imag} imagined vs K={k_real} real frames"}
    digests = _chunk0(store, pair.imagined), _chunk0(store, pair.real)
    if digests[0] is not None and digests[1] is not None:
        if digests[0] != digests[1]:
            return k_imag, {"pair": pair.pair_id, "reason": "the first policy chunks differ (extra.chunk0)"}
        return k_imag, None
    diff = np.abs(a_imag.astype(np.float64) - a_real.astype(np.float64)).max(axis=1)  # per frame
    if float(diff.max()) > atol:
        return k_imag, {
            "pair": pair.pair_id,
            "reason": "round-0 actions differ (the real branch stores the safety-filtered command)",
            "max_abs_action_diff": float(diff.max()),
            "first_differing_row": int(np.argmax(diff > atol)),
        }
    return k_imag, None


def _summary(scores: SingleStepScores, frozen: SingleStepScores) -> dict[str, Any]:
    out = scores.summarize()
    base = frozen.summarize()
    out["frozen"] = {k: base[k] for k in ("psnr", "psnr_pooled", "ssim", "exact", "per_view", "per_frame")}
    out["gain_over_frozen_pooled_db"] = out["psnr_pooled"] - base["psnr_pooled"]
    for v, d in out["per_view"].items():
        d["gain_over_frozen_pooled_db"] = d["psnr_pooled"] - base["per_view"][v]["psnr_pooled"]
    return out


def single_step_metrics(
    store: EpisodeStore,
    pairs: Sequence[Pair],
    *,
    action_atol: float = DEFAULT_ACTION_ATOL,
    lpips: bool = True,
    lpips_weights: Path | None = None,
) -> dict[str, Any]:
    """Single-step PSNR / SSIM (/ LPIPS) of the usable pairs, overall and per task.

    Returns ``{protocol, video_mode, K, views, pairs, pairs_used, pairs_skipped, skipped: [...],
    starts_identical, psnr, psnr_pooled, ssim, exact, [lpips], lpips_reason, per_view: {view: {...}},
    per_frame: {metric: [K values]}, frozen: {...}, gain_over_frozen_pooled_db, tasks: {task: {...}}}``;
    with no usable pair the metric keys are absent and ``reason`` says why.
    """
    lpips_fn: LpipsFn | None
    lpips_fn, lpips_reason = load_lpips(lpips_weights) if lpips else (None, "disabled by the caller")
    views = list(store.spec.views)
    out: dict[str, Any] = {
        "protocol": PROTOCOL,
        "video_mode": store.spec.video_mode,
        "action_atol": action_atol,
        "views": views,
        "pairs": len(pairs),
        "lpips_reason": lpips_reason,
    }
    overall = (SingleStepScores(lpips_fn), SingleStepScores())
    per_task: dict[str, tuple[SingleStepScores, SingleStepScores]] = {}
    skipped: list[dict[str, Any]] = []
    run_k: int | None = None
    starts_identical = 0
    for pair in pairs:
        k, problem = _check_pair(store, pair, action_atol)
        if run_k is None and k >= 1:
            run_k = k  # the first pair's K is the run's (ChunkSpec.frames)
        if problem is None and k != run_k:
            problem = {"pair": pair.pair_id, "reason": f"K={k} differs from the run's K={run_k}"}
        if problem is not None:
            skipped.append(problem)
            continue
        imag = {v: store.frames(pair.imagined, v, 0, k + 1) for v in views}
        real = {v: store.frames(pair.real, v, 0, k + 1) for v in views}
        starts_identical += int(all(np.array_equal(imag[v][0], real[v][0]) for v in views))
        pred = _clip({v: imag[v][1:] for v in views}, views)
        target = _clip({v: real[v][1:] for v in views}, views)
        still = _clip({v: np.repeat(real[v][:1], k, axis=0) for v in views}, views)
        if pair.task not in per_task:
            per_task[pair.task] = (SingleStepScores(lpips_fn), SingleStepScores())
        model_values, frozen_values = overall[0].score(pred, target), overall[1].score(still, target)
        for model_scores, frozen_scores in (overall, per_task[pair.task]):
            model_scores.add_scores(model_values, views)
            frozen_scores.add_scores(frozen_values, views)
    out |= {
        "K": run_k,
        "pairs_used": overall[0].samples,
        "pairs_skipped": len(skipped),
        "skipped": skipped,
        "starts_identical": starts_identical,
    }
    if overall[0].samples == 0:
        out["reason"] = f"no usable pair ({len(skipped)} skipped, see 'skipped')" if skipped else "no pairs"
        return out
    out |= _summary(*overall)
    out.setdefault("lpips", None)  # absent: lpips_reason says why
    out["tasks"] = {task: _summary(*s) for task, s in sorted(per_task.items())}
    return out
