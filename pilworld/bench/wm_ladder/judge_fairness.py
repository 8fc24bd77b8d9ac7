"""Rung 2, judge fairness: the plain real episodes judged again after each degradation, with one injected fault.

Judged by the hand-written reference judge and, beside it, the learned judge of the settings (the shipped one
by default): a fair judge's agreement with the checker does not drop on frames that are degraded but right
(docs/judges.md, "Fairness").
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np

from pilworld.bench.wm_ladder.degrade import degrade_episode
from pilworld.bench.wm_ladder.lab import Lab
from pilworld.bench.wm_ladder.model import FrameAutoencoder, autoencoder_for
from pilworld.bench.wm_ladder.settings import DEGRADATIONS
from pilworld.bench.wm_ladder.stats import (
    frame_mse,
    judge_summary,
    judgement,
    learned_judgement,
    learned_summary,
    mean_ci,
    psnr,
)
from pilworld.paired.runner import PairedSubtask


def judge_fairness_record(
    lab: Lab, pair: PairedSubtask, index: int, *, degradations: Sequence[str] = DEGRADATIONS
) -> dict[str, Any]:
    from pilworld.bench.hallucination import inject_random
    from pilworld.judges.faults import FAULTS
    from pilworld.judges.hallucination import HallucinationDetector
    from pilworld.judges.vision import VisionJudge

    rollout, real_ok = lab.real(pair)
    ep = lab.episode(pair, rollout)
    ctx = lab.context(pair.subtask.task)
    judge, detector = VisionJudge(), HallucinationDetector()
    ae = autoencoder_for(lab.model(pair.subtask.task)[0]) if "autoencoded" in degradations else None
    fault = FAULTS[index % len(FAULTS)]  # every degradation of a pair gets the same fault at the same frame
    rec: dict[str, Any] = {"real": real_ok, "fault": fault}
    for d in degradations:
        noise = np.random.default_rng([lab.cfg.seed0, index, 17])
        degraded = degrade_episode(ep, d, autoencode=ae if isinstance(ae, FrameAutoencoder) else None, rng=noise)
        row: dict[str, Any] = judgement(judge.judge(degraded, ctx))
        if lab.learned is not None:
            row["learned"] = learned_judgement(lab.learned.judge(degraded, ctx))
        row["mse"] = {v: frame_mse(degraded.images[v], ep.images[v]) for v in ep.images}
        case = inject_random(fault, degraded, lab.rig_cfg, np.random.default_rng([lab.cfg.seed0, index, 21]))
        if case is None:
            row["fault_outcome"] = "skipped"
        else:
            faulted, k = case
            f = detector.judge(faulted, ctx).first_hallucination_frame
            row["fault_k"] = k
            row["fault_frame"] = f
            row["fault_outcome"] = (
                "missed" if f is None else "detected" if abs(f - k) <= 1 else "early" if f < k else "late"
            )
        rec[d] = row
    return rec


def judge_fairness_summary(
    records: Sequence[tuple[PairedSubtask, dict[str, Any]]], degradations: Sequence[str]
) -> dict[str, Any]:
    out: dict[str, Any] = {"n": len(records), "degradations": list(degradations)}
    for d in degradations:
        rows = [(bool(r["real"]), r[d]) for _, r in records]
        outcomes = [j["fault_outcome"] for _, j in rows]
        counts = {o: outcomes.count(o) for o in ("detected", "early", "late", "missed", "skipped")}
        recall = mean_ci([o == "detected" for o in outcomes if o != "skipped"])
        views = list(rows[0][1]["mse"]) if rows else []
        learned = [(t, j["learned"]) for t, j in rows if "learned" in j]
        if learned and len(learned) == len(rows):
            plain = [r["plain"]["learned"] for _, r in records] if d != "plain" and "plain" in degradations else None
            out.setdefault("learned", {})[d] = learned_summary(learned, plain)
        out[d] = {
            **judge_summary(rows),
            "fault_recall": recall["rate"],
            "fault_recall_ci95": recall["ci95"],
            "fault_n": recall["n"],
            "fault_outcomes": counts,
            "psnr_vs_plain": {v: psnr(float(np.mean([j["mse"][v] for _, j in rows]))) for v in views},
        }
    out["sr_checker"] = mean_ci([bool(r["real"]) for _, r in records])
    out["fault_types"] = {
        f: sum(1 for _, r in records if r["fault"] == f) for f in dict.fromkeys(r["fault"] for _, r in records)
    }
    return out
