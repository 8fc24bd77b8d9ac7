"""Rung 1, representation: the real branch with every frame the policy sees through the model's autoencoder."""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence
from typing import Any

import numpy as np

from pilworld.bench.wm_ladder.envs import AutoencodedEnv
from pilworld.bench.wm_ladder.lab import Lab
from pilworld.bench.wm_ladder.model import FrameAutoencoder, autoencoder_for
from pilworld.bench.wm_ladder.stats import judge_summary, judgement, paired_rates, per_task, psnr
from pilworld.paired.runner import PairedSubtask


def representation_record(lab: Lab, pair: PairedSubtask, index: int) -> dict[str, Any]:
    from pilworld.judges.vision import VisionJudge

    model, _, _ = lab.model(pair.subtask.task)
    ae = autoencoder_for(model)
    assert isinstance(ae, FrameAutoencoder)
    judge, ctx = VisionJudge(), lab.context(pair.subtask.task)
    rollout, real_ok = lab.real(pair)
    plain = judgement(judge.judge(lab.episode(pair, rollout), ctx))
    ae_rollout, env, ae_ok = lab.run_branch(pair, lambda e: AutoencodedEnv(e, ae))
    # The policy saw the autoencoded start: store that as frame 0 of the autoencoded episode.
    ae_rollout = dataclasses.replace(
        ae_rollout, start=dataclasses.replace(ae_rollout.start, observation=env.start_observation)
    )
    autoencoded = judgement(judge.judge(lab.episode(pair, ae_rollout), ctx))
    return {
        "real": real_ok,
        "autoencoded": ae_ok,
        "judge_plain": plain,
        "judge_autoencoded": autoencoded,
        "ae_mse": {v: float(np.mean(m)) for v, m in env.mse.items()},
    }


def representation_summary(records: Sequence[tuple[PairedSubtask, dict[str, Any]]]) -> dict[str, Any]:
    cols = {k: [bool(r[k]) for _, r in records] for k in ("real", "autoencoded")}
    views = list(records[0][1]["ae_mse"]) if records else []
    return {
        "n": len(records),
        **paired_rates(cols, "real"),
        "per_task": per_task(records, ("real", "autoencoded")),
        "judges": {
            "plain": judge_summary([(bool(r["real"]), r["judge_plain"]) for _, r in records]),
            "autoencoded": judge_summary([(bool(r["autoencoded"]), r["judge_autoencoded"]) for _, r in records]),
        },
        "autoencoder_psnr": {
            **{v: psnr(float(np.mean([r["ae_mse"][v] for _, r in records]))) for v in views},
            "all": psnr(float(np.mean([np.mean(list(r["ae_mse"].values())) for _, r in records]))) if views else None,
        },
    }
