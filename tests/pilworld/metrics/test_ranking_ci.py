"""Bootstrap intervals of Pearson, Spearman and MMRV across settings (``ranking_intervals``), and their
place in ``metrics.json`` (``overall.ranking_ci95``).
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from pilworld.data.outcomes import Outcome, record_outcomes
from pilworld.data.pairs import Pair
from pilworld.metrics import compute_run_metrics
from pilworld.metrics.ranking import mmrv, pearson, spearman
from pilworld.metrics.ranking_ci import ranking_intervals
from pilworld.metrics.success import PairScore
from tests.pilworld.metrics.synthetic import ROUNDS, K, SynthPair, write_paired

RESAMPLES = 400


def _score(task: str, ckpt: str, i: int, real: float | None, imag: float | None) -> PairScore:
    pair = Pair(f"{task}/{ckpt}/seed0/subtask{i}", task, ckpt, imagined=2 * i, real=2 * i + 1)
    return PairScore(
        pair=pair,
        real=real,
        imag=imag,
        judges=("vision",),
        checker=None,
        hfr=None,
        hfr_judges=(),
    )


def _scores(plan: dict[tuple[str, str], list[tuple[float | None, float | None]]]) -> list[PairScore]:
    out, i = [], 0
    for (task, ckpt), pairs in plan.items():
        for real, imag in pairs:
            out.append(_score(task, ckpt, i, real, imag))
            i += 1
    return out


def _tracking() -> list[PairScore]:
    """Four settings of 8 pairs with real success rates 1/8, 3/8, 5/8, 7/8; each imagined verdict = the real one."""
    plan: dict[tuple[str, str], list[tuple[float | None, float | None]]] = {}
    for k, wins in enumerate((1, 3, 5, 7)):
        plan[("t", f"c{k}")] = [(float(j < wins), float(j < wins)) for j in range(8)]
    return _scores(plan)


def _noisy(seed: int = 3) -> tuple[list[PairScore], list[float], list[float]]:
    """Five settings of 20 pairs, imagined success tracking the real rate with noise; also the setting means."""
    rng = np.random.default_rng(seed)
    plan: dict[tuple[str, str], list[tuple[float | None, float | None]]] = {}
    for k, p in enumerate((0.1, 0.3, 0.5, 0.7, 0.9)):
        real = rng.random(20) < p
        imag = rng.random(20) < min(1.0, p + 0.05)
        plan[("t", f"c{k}")] = [(float(r), float(i)) for r, i in zip(real, imag, strict=True)]
    scores = _scores(plan)
    sr_real = [float(np.mean([r for r, _ in v])) for v in plan.values()]
    sr_imag = [float(np.mean([i for _, i in v])) for v in plan.values()]
    return scores, sr_real, sr_imag


def test_a_perfectly_tracking_model_gives_pearson_one_and_mmrv_zero() -> None:
    out = ranking_intervals(_tracking(), resamples=RESAMPLES, seed=0)
    assert out["n_settings"] == 4 and out["resamples"] == RESAMPLES and "reason" not in out
    assert out["pearson"] == pytest.approx([1.0, 1.0])
    assert out["spearman"] == pytest.approx([1.0, 1.0])
    assert out["mmrv"] == [0.0, 0.0]
    assert out["mmrv_defined"] == RESAMPLES
    # Pearson is undefined only in a draw that made every setting's rate equal, which is rare here.
    assert RESAMPLES - 5 <= out["pearson_defined"] <= RESAMPLES


def test_a_constant_imagined_rate_leaves_pearson_undefined() -> None:
    plan: dict[tuple[str, str], list[tuple[float | None, float | None]]] = {
        ("t", f"c{k}"): [(float(j < wins), 1.0) for j in range(6)] for k, wins in enumerate((1, 3, 5))
    }
    out = ranking_intervals(_scores(plan), resamples=RESAMPLES, seed=0)
    assert out["pearson"] is None and out["pearson_defined"] == 0
    assert out["spearman"] is None and out["spearman_defined"] == 0
    # MMRV is defined for constant vectors: a tie in SR_imag where SR_real differs is a violation.
    assert out["mmrv_defined"] == RESAMPLES
    lo, hi = out["mmrv"]
    assert 0.0 < lo <= hi <= 1.0


def test_fewer_than_two_settings_give_no_intervals() -> None:
    one = _scores({("t", "c0"): [(1.0, 1.0), (0.0, 1.0)], ("t", "c1"): [(None, 1.0), (1.0, None)]})
    out = ranking_intervals(one, resamples=RESAMPLES, seed=0)
    assert out["n_settings"] == 1  # setting c1 has no pair with both branches judged
    for name in ("pearson", "spearman", "mmrv"):
        assert out[name] is None and out[f"{name}_defined"] == 0
    assert "fewer than 2 settings" in out["reason"]
    assert ranking_intervals([], resamples=RESAMPLES)["n_settings"] == 0
    none = ranking_intervals(_tracking(), resamples=0)
    assert none["pearson"] is None and none["reason"] == "no resamples"


def test_the_seed_decides_the_result() -> None:
    scores, _, _ = _noisy()
    a = ranking_intervals(scores, resamples=RESAMPLES, seed=5)
    assert ranking_intervals(scores, resamples=RESAMPLES, seed=5) == a
    b = ranking_intervals(scores, resamples=RESAMPLES, seed=6)
    assert b != a and b["seed"] == 6


def test_intervals_contain_the_point_estimates() -> None:
    scores, sr_real, sr_imag = _noisy()
    out = ranking_intervals(scores, resamples=2000, seed=0)
    points = {
        "pearson": pearson(sr_imag, sr_real),
        "spearman": spearman(sr_imag, sr_real),
        "mmrv": mmrv(sr_imag, sr_real),
    }
    assert points["pearson"] is not None and points["pearson"] > 0.8  # a clear case
    for name, point in points.items():
        assert point is not None
        lo, hi = out[name]
        assert lo <= point <= hi, (name, lo, point, hi)
        assert hi > lo, name  # 20 noisy pairs per setting: a real spread
    assert out["pearson"][1] <= 1.0 and out["mmrv"][0] >= 0.0
    json.dumps(out, allow_nan=False)


def test_the_order_of_the_settings_does_not_matter() -> None:
    """Settings are resampled in sorted order, so listing them in another order gives the same intervals."""
    scores, _, _ = _noisy()
    by_setting = sorted(scores, key=lambda s: s.pair.checkpoint, reverse=True)  # c4's pairs first; stable within
    assert by_setting[0].pair.checkpoint == "c4"
    assert ranking_intervals(by_setting, resamples=RESAMPLES, seed=1) == ranking_intervals(
        scores, resamples=RESAMPLES, seed=1
    )


@pytest.fixture(scope="module")
def run(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A synthetic run with three settings whose imagined verdicts equal the real ones."""
    plan = [("a", "c1", 1), ("a", "c1", 1), ("a", "c2", 1), ("a", "c2", 0), ("b", "c1", 0), ("b", "c1", 0)]
    root = tmp_path_factory.mktemp("ranking_ci") / "run"
    write_paired(root, [SynthPair(task=t, checkpoint=c, subtask=i) for i, (t, c, _) in enumerate(plan)])
    T = 1 + ROUNDS * K
    verdicts = []
    for i, (*_, ok) in enumerate(plan):
        verdicts.append(Outcome(2 * i, "vision", "vision", bool(ok), T))
        verdicts.append(Outcome(2 * i + 1, "vision", "vision", bool(ok), T))
    record_outcomes(root, verdicts)
    return root


def test_run_metrics_carry_the_ranking_intervals(run: Path) -> None:
    m = compute_run_metrics(run, bootstrap=300, seed=2, single_step=False)
    ci = m["overall"]["ranking_ci95"]
    json.dumps(m, allow_nan=False)
    assert (ci["resamples"], ci["seed"], ci["n_settings"]) == (300, 2, 3)
    assert m["overall"]["pearson"] == 1.0 and m["overall"]["mmrv"] == 0.0
    assert ci["pearson"] == pytest.approx([1.0, 1.0]) and ci["mmrv"] == [0.0, 0.0]
    assert 0 < ci["pearson_defined"] <= 300
    assert compute_run_metrics(run, bootstrap=0, single_step=False)["overall"]["ranking_ci95"] is None
