"""metrics.json of a synthetic multi-task run: hand-computed settings, ranking, task means, JSON validity."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from pilworld.data.outcomes import Outcome, record_outcomes
from pilworld.metrics import compute_run_metrics, write_metrics
from pilworld.metrics.report import main, rounded
from tests.pilworld.metrics.synthetic import ROUNDS, K, SynthPair, write_paired

T = 1 + ROUNDS * K
# (task, checkpoint, real success, imagined success, imagined t_h) per pair.
PLAN = [
    ("a", "c1", 1, 1, None),
    ("a", "c1", 1, 0, 3),
    ("a", "c2", 0, 0, None),
    ("a", "c2", 1, 0, None),
    ("b", "c1", 0, 1, None),
    ("b", "c1", 0, 0, 5),
]


@pytest.fixture(scope="module")
def run(tmp_path_factory: pytest.TempPathFactory) -> Path:
    root = tmp_path_factory.mktemp("report") / "run"
    write_paired(root, [SynthPair(task=t, checkpoint=c, subtask=i) for i, (t, c, *_) in enumerate(PLAN)])
    verdicts = []
    for i, (_, _, real, imag, t_h) in enumerate(PLAN):
        verdicts.append(Outcome(2 * i, "vision", "vision", bool(imag), T, t_h))
        verdicts.append(Outcome(2 * i + 1, "vision", "vision", bool(real), T))
        verdicts.append(Outcome(2 * i + 1, "sim_checker", "sim_state", True, T))
    record_outcomes(root, verdicts)
    return root


def test_layout_and_hand_computed_values(run: Path) -> None:
    m = compute_run_metrics(run, bootstrap=200, lpips=False)
    json.dumps(m, allow_nan=False)
    assert [(s["task"], s["checkpoint"], s["sr_real"], s["sr_imag"], s["n"]) for s in m["settings"]] == [
        ("a", "c1", 1.0, 0.5, 2),
        ("a", "c2", 0.5, 0.0, 2),
        ("b", "c1", 0.0, 0.5, 2),
    ]
    a, b, overall = m["tasks"]["a"], m["tasks"]["b"], m["overall"]
    for t in (a, b):
        assert {"sr_real", "sr_imag", "abs_delta_sr", "hfr", "sr_real_checker", "n_subtasks", "ci95"} <= set(t)
    assert (a["sr_real"], a["sr_imag"], a["abs_delta_sr"], a["n_subtasks"]) == (0.75, 0.25, 0.5, 4)
    assert (b["sr_real"], b["sr_imag"], b["abs_delta_sr"]) == (0.0, 0.5, 0.5)
    assert a["hfr"] == pytest.approx((1 + 3 / T + 1 + 1) / 4, abs=1e-6) and a["sr_real_checker"] == 1.0
    # Overall |ΔSR| is over all pairs: |2/6 − 3/6|; the paper's "average gap" is the task mean.
    assert overall["sr_real"] == 0.5 and overall["sr_imag"] == pytest.approx(1 / 3, abs=1e-6)
    assert overall["abs_delta_sr"] == pytest.approx(1 / 6, abs=1e-6) and overall["abs_delta_sr_task_mean"] == 0.5
    # Across settings: SR_imag (.5, 0, .5) vs SR_real (1, .5, 0): centred products sum to 0 → r = 0;
    # MMRV: setting 0 ties setting 2 in imag but is 1 above it in real (1), settings 1 and 2 swap (.5, .5).
    assert overall["pearson"] == 0.0 and overall["spearman"] == 0.0
    assert overall["mmrv"] == pytest.approx(2 / 3, abs=1e-6)
    assert (overall["n_settings"], overall["n_settings_ranked"], overall["n_tasks"]) == (3, 3, 2)
    assert a["across_checkpoints"]["pearson"] == 1.0 and a["across_checkpoints"]["mmrv"] == 0.0
    assert b["across_checkpoints"]["pearson"] is None and "fewer than 2" in b["across_checkpoints"]["pearson_reason"]
    for key in ("sr_real", "sr_imag", "hfr", "abs_delta_sr"):
        lo, hi = overall["ci95"][key]
        assert lo <= overall[key] <= hi
    assert m["judges"]["success"] == ["vision"] and m["judges"]["checker"] == ["sim_checker"]
    assert m["single_step"]["pairs_used"] == 6 and len(m["single_step"]["per_frame"]["ssim"]) == K


def test_write_metrics_and_the_module_entry_point(run: Path, tmp_path: Path) -> None:
    written = write_metrics(run, tmp_path / "m.json", bootstrap=50, single_step=False)
    assert json.loads((tmp_path / "m.json").read_text()) == written
    assert written["single_step"] == {"reason": "disabled by the caller"}
    assert main([str(run), "--out", str(tmp_path / "cli.json"), "--bootstrap", "0", "--no-single-step"]) == 0
    cli = json.loads((tmp_path / "cli.json").read_text())
    assert cli["overall"]["ci95"] is None and cli["overall"]["pearson"] == 0.0


def test_rounding_keeps_six_significant_digits_and_refuses_nan() -> None:
    assert rounded({"a": [1 / 3, 1e-5, 22.809512345], "b": None, "c": 3}) == {
        "a": [0.333333, 1e-05, 22.8095],
        "b": None,
        "c": 3,
    }
    with pytest.raises(ValueError, match="non-finite"):
        rounded({"x": float("nan")})
