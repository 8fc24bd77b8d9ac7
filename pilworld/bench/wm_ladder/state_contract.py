"""Rung 0, the state contract: perfect images, but the imagined branch's state (the commanded joints)."""

from __future__ import annotations

from collections.abc import Sequence
from functools import partial
from typing import Any

import numpy as np

from pilworld.bench.wm_ladder.envs import StateContractEnv
from pilworld.bench.wm_ladder.lab import Lab
from pilworld.bench.wm_ladder.settings import STATE_MODES
from pilworld.bench.wm_ladder.stats import paired_rates, per_task
from pilworld.paired.runner import PairedSubtask


def state_contract_record(lab: Lab, pair: PairedSubtask, index: int) -> dict[str, Any]:
    _, real_ok = lab.real(pair)
    rec: dict[str, Any] = {"real": real_ok}
    for mode in STATE_MODES[1:]:
        _, env, ok = lab.run_branch(pair, partial(StateContractEnv, mode=mode))
        rec[mode] = ok
        gaps = np.array(env.gaps, dtype=np.float64).reshape(-1, 2)
        rec[f"{mode}_gap"] = [round(float(gaps[:, 0].mean()), 5), round(float(gaps[:, 1].mean()), 5)]
    return rec


def state_contract_summary(records: Sequence[tuple[PairedSubtask, dict[str, Any]]]) -> dict[str, Any]:
    cols = {m: [bool(r[m]) for _, r in records] for m in STATE_MODES}
    gaps = {m: np.array([r[f"{m}_gap"] for _, r in records], dtype=np.float64) for m in STATE_MODES[1:]}
    return {
        "n": len(records),
        "modes": list(STATE_MODES),
        **paired_rates(cols, "real"),
        "per_task": per_task(records, STATE_MODES),
        "state_gap": {
            m: {"arms_rad": round(float(g[:, 0].mean()), 5), "grippers": round(float(g[:, 1].mean()), 5)}
            for m, g in gaps.items()
        },
    }
