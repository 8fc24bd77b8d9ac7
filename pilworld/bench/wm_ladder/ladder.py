"""The ladder: every rung of a :class:`LadderConfig` run (or resumed) in turn, and its human summary."""

from __future__ import annotations

import dataclasses
import time
from functools import partial
from typing import Any

import torch

from pilworld.bench.common import machine_info
from pilworld.bench.wm_ladder.judge_fairness import judge_fairness_record, judge_fairness_summary
from pilworld.bench.wm_ladder.lab import Lab, each_pair
from pilworld.bench.wm_ladder.model import FrameAutoencoder, autoencoder_for
from pilworld.bench.wm_ladder.representation import representation_record, representation_summary
from pilworld.bench.wm_ladder.settings import DEGRADATIONS, HEAD, LadderConfig
from pilworld.bench.wm_ladder.state_contract import state_contract_record, state_contract_summary
from pilworld.bench.wm_ladder.teacher_forced import teacher_forced_record, teacher_forced_summary
from pilworld.io.atomic import write_json


def run_wm_ladder(cfg: LadderConfig, *, progress: bool = True) -> dict[str, Any]:
    """Run (or resume) the rungs of ``cfg``; returns the JSON-friendly result (see the module doc)."""
    t_start = time.monotonic()
    lab = Lab(cfg)
    plan = cfg.plan()
    result: dict[str, Any] = {
        "bench": "wm-ladder",
        "quick": cfg.quick,
        "model": str(lab.model_path),
        "rig": str(cfg.rig),
        "tasks": list(cfg.tasks),
        "checkpoints": list(cfg.checkpoint_names),
        "subtasks_per_setting": cfg.subtasks_per_setting,
        "n_pairs": len(plan),
        "seeds": {
            "layout_seed0": cfg.seed0,
            "layout_seeds": sorted({p.subtask.seed for p in plan}),
            "policy_and_model_seed": "layout_seed * 100 + subtask_index (the paired runner's pair seed)",
        },
        "spec": dataclasses.asdict(cfg.spec),
        "rungs": list(cfg.rungs),
        "out": str(lab.out),
        "skipped": {},
        "seconds": {},
    }
    try:
        model, _, resized = lab.model(cfg.tasks[0])  # a bad model fails before anything runs
        result["model_resized"] = resized
        result["adapters"] = {t: lab.model(t)[1] for t in cfg.tasks} if set(cfg.rungs) - {"state_contract"} else None
        ae = autoencoder_for(model)
        views = list(model.info.views)
        for rung in cfg.rungs:
            t0 = time.monotonic()
            runs0 = lab.real_runs
            if rung == "state_contract":
                recs = each_pair(
                    lab, rung, {"real": lab.real_key}, plan, lambda p, i: state_contract_record(lab, p, i), progress
                )
                result[rung] = state_contract_summary(recs)
            elif rung == "representation":
                if isinstance(ae, str):
                    result[rung] = None
                    result["skipped"][rung] = ae
                    continue
                recs = each_pair(
                    lab, rung, {"model": lab.model_key}, plan, lambda p, i: representation_record(lab, p, i), progress
                )
                result[rung] = representation_summary(recs)
            elif rung == "judge_fairness":
                degr = [d for d in DEGRADATIONS if d != "autoencoded" or isinstance(ae, FrameAutoencoder)]
                if isinstance(ae, str):
                    result["skipped"]["judge_fairness.autoencoded"] = ae
                key = {
                    "model": lab.model_key if isinstance(ae, FrameAutoencoder) else lab.real_key,
                    "d": degr,
                    "judge": lab.judge_key,
                }
                recs = each_pair(lab, rung, key, plan, partial(judge_fairness_record, lab, degradations=degr), progress)
                result[rung] = judge_fairness_summary(recs, degr)
                if isinstance(ae, str):
                    result[rung]["autoencoded"] = None
            elif rung == "teacher_forced":
                key = {"model": lab.model_key, "judge": lab.judge_key}
                recs = each_pair(lab, rung, key, plan, lambda p, i: teacher_forced_record(lab, p, i), progress)
                result[rung] = teacher_forced_summary(recs, views)
            result[rung]["seeds"] = result["seeds"]["layout_seeds"]
            result[rung]["real_branches_run"] = lab.real_runs - runs0
            result["seconds"][rung] = round(time.monotonic() - t0, 1)
            write_json(lab.out / f"{rung}.json", result[rung], durable=False)
    finally:
        lab.close()
    result["wall_seconds"] = round(time.monotonic() - t_start, 1)
    result["machine"] = {**machine_info(), "torch_threads": torch.get_num_threads()}
    write_json(lab.out / "ladder.json", result, durable=False)
    return result


def summary_lines(r: dict[str, Any]) -> list[str]:
    """The human summary the CLI prints above the JSON."""

    def pct(x: Any) -> str:
        return "-" if x is None else f"{100 * x:.0f}%"

    def ci(x: Any) -> str:
        return "" if not x else f" [{100 * x[0]:.0f}, {100 * x[1]:.0f}]"

    lines = [
        f"wm-ladder ({'quick' if r['quick'] else 'full'}): {r['n_pairs']} pairs, model {r['model']}, "
        f"{r['wall_seconds']} s"
    ]
    s = r.get("state_contract")
    if s:
        lines.append(
            "  0 state contract  SR " + ", ".join(f"{m} {pct(s['sr'][m])}{ci(s['sr_ci95'][m])}" for m in s["modes"])
        )
    if "representation" in r:
        rep = r["representation"]
        if rep is None:
            lines.append(f"  1 representation  skipped: {r['skipped'].get('representation')}")
        else:
            j = rep["judges"]
            lines.append(
                f"  1 representation  SR real {pct(rep['sr']['real'])}, autoencoded {pct(rep['sr']['autoencoded'])}; "
                f"judge agreement plain {pct(j['plain']['agreement'])} / AE {pct(j['autoencoded']['agreement'])}, "
                f"hallucination FP plain {pct(j['plain']['hallucination_fp_rate'])} / AE "
                f"{pct(j['autoencoded']['hallucination_fp_rate'])}; AE PSNR {rep['autoencoder_psnr']}"
            )
    jf = r.get("judge_fairness")
    if jf:
        parts = [
            f"{d}: agree {pct(jf[d]['agreement'])} FP {pct(jf[d]['hallucination_fp_rate'])} "
            f"recall {pct(jf[d]['fault_recall'])}"
            for d in jf["degradations"]
        ]
        lines.append("  2 judge fairness  " + "; ".join(parts))
    tf = r.get("teacher_forced")
    if tf:
        lines.append("  3 teacher forced  round    " + "".join(f"{row['round']:>7}" for row in tf["rounds"]))
        for k in ("teacher_forced", "free", "frozen", "frozen_start"):
            lines.append(f"    head PSNR {k:<14}" + "".join(f"{row[k][HEAD]:>7.2f}" for row in tf["rounds"]))
    return lines
