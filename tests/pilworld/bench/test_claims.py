"""Per-pair agreement and the paper's claims as paired comparisons (:mod:`pilworld.bench.claims`)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from pilworld.bench.claims import (
    PAPER_CLAIMS,
    Verdicts,
    agreement,
    compare,
    direction,
    paper_claims,
    steps,
    wilson,
)
from pilworld.data.outcomes import Outcome, record_outcomes
from tests.pilworld.metrics.synthetic import ROUNDS, K, SynthPair, write_paired


def _verdicts(real: list[int], imag: list[int], hfr: list[float] | None = None, task: str = "t") -> Verdicts:
    hfr = hfr or [1.0] * len(real)
    return Verdicts(
        {f"p{i}": (task, float(r), float(m), h) for i, (r, m, h) in enumerate(zip(real, imag, hfr, strict=True))}
    )


def test_wilson_matches_the_formula_and_stays_inside_0_1() -> None:
    lo, hi = wilson(150, 161) or [0.0, 0.0]
    assert lo == pytest.approx(0.8817, abs=1e-3) and hi == pytest.approx(0.9613, abs=1e-3)
    zero = wilson(0, 10)
    assert zero is not None and zero[0] == 0.0 and 0.25 < zero[1] < 0.35
    full = wilson(10, 10)
    assert full is not None and full[1] == 1.0 and 0.65 < full[0] < 0.75
    assert wilson(0, 0) is None


def test_agreement_counts_and_tasks() -> None:
    v = Verdicts(
        {
            "a": ("x", 1.0, 1.0, 1.0),
            "b": ("x", 1.0, 0.0, 1.0),
            "c": ("x", 0.0, 0.0, 1.0),
            "d": ("y", 0.0, 1.0, 1.0),
            "e": ("y", 0.0, 0.0, 1.0),
        }
    )
    a = agreement(v)
    assert (a["successes"]["k"], a["successes"]["n"]) == (1, 2)
    assert (a["failures"]["k"], a["failures"]["n"]) == (2, 3)
    assert (a["all"]["k"], a["all"]["n"]) == (3, 5) and a["all"]["share"] == pytest.approx(0.6)
    assert a["tasks"]["y"]["successes"] == {"k": 0, "n": 0, "share": None, "ci95": None}
    assert a["tasks"]["x"]["failures"]["share"] == 1.0


def test_compare_is_paired_and_signed() -> None:
    rng = np.random.default_rng(0)
    real = [int(x) for x in rng.random(200) < 0.5]
    good = _verdicts(real, real, [0.95] * 200)  # imagines exactly the real verdict
    flipped = [1 - r if i % 3 == 0 else r for i, r in enumerate(real)]
    bad = _verdicts(real, flipped, [0.80] * 200)
    c = compare(good, bad, resamples=500)
    assert c["pairs"] == 200
    assert c["difference"]["agreement"] == pytest.approx(sum(1 for i in range(200) if i % 3 == 0) / 200)
    assert c["difference"]["hfr"] == pytest.approx(0.15)
    lo, hi = c["ci95"]["agreement"]
    assert 0 < lo <= c["difference"]["agreement"] <= hi
    assert direction(c["difference"]["agreement"], c["ci95"]["agreement"], 1.0) == "holds"
    assert direction(-0.1, [-0.2, -0.05], 1.0) == "reversed"
    assert direction(-0.1, [-0.2, -0.05], -1.0) == "holds"  # lower |ΔSR| is better
    assert direction(0.0, [-0.1, 0.1], 1.0) == "not separated"
    assert direction(0.0, None, 1.0) == "undefined"
    same = compare(good, good, resamples=200)
    assert same["difference"] == {"abs_delta_sr": 0.0, "hfr": 0.0, "agreement": 0.0}


def test_compare_refuses_unshared_real_branches_and_no_common_pairs() -> None:
    a = _verdicts([1, 0, 1], [1, 0, 1])
    with pytest.raises(ValueError, match="real verdicts differ"):
        compare(a, _verdicts([0, 0, 1], [1, 0, 1]))
    with pytest.raises(ValueError, match="no judged pair in common"):
        compare(a, Verdicts({"other": ("t", 1.0, 1.0, 1.0)}))


def test_paper_claims_only_for_variants_that_ran() -> None:
    real = [1, 0] * 30
    runs = {"pilworld": _verdicts(real, real), "v2_no_history": _verdicts(real, [1] * 60)}
    claims = paper_claims(runs, resamples=300)
    assert [c["claim"] for c in claims] == ["history"]
    c = claims[0]
    assert (c["better"], c["worse"]) == ("pilworld", "v2_no_history")
    # The history-less variant imagines every failure a success: |ΔSR| 0.5 worse, agreement 0.5 worse.
    assert c["difference"]["abs_delta_sr"] == pytest.approx(-0.5)
    assert c["direction"] == {"abs_delta_sr": "holds", "hfr": "not separated", "agreement": "holds"}
    assert {n for n, *_ in PAPER_CLAIMS} >= {"control_video_vs_tokens", "history", "failure_data"}


def test_verdicts_load_from_a_judged_run(tmp_path: Path) -> None:
    root = write_paired(tmp_path / "run", [SynthPair(subtask=i) for i in range(3)])
    T = 1 + ROUNDS * K
    record_outcomes(
        root,
        [
            Outcome(0, "vision", "vision", True, T, first_hallucination_frame=T // 2),
            Outcome(1, "vision", "vision", True, T),
            Outcome(2, "vision", "vision", False, T),
            Outcome(3, "vision", "vision", True, T),
        ],
    )
    v = Verdicts.load(root)
    assert len(v.pairs) == 2  # the third pair has no verdict
    rows = sorted(v.pairs.values(), key=lambda r: r[2])
    assert [(r[1], r[2]) for r in rows] == [(1.0, 0.0), (1.0, 1.0)]
    assert rows[1][3] == pytest.approx((T // 2) / T)


def test_steps_compare_each_row_with_the_one_before_and_skip_missing_rows() -> None:
    real = [1, 1, 0, 0] * 10
    worst = _verdicts(real, [0] * 40, [0.1] * 40)
    middle = _verdicts(real, [1, 0, 0, 0] * 10, [0.5] * 40)
    best = _verdicts(real, real, [0.9] * 40)
    out = steps({"a": worst, "b": middle, "c": best}, ["a", "missing", "b", "c"], resamples=200)
    assert [(s["from"], s["to"]) for s in out] == [("a", "b"), ("b", "c")]
    # a → b: one in four pairs now agrees (the real successes half-imagined), HFR +0.4 on every pair.
    assert out[0]["difference"]["agreement"] == pytest.approx(0.25)
    assert out[0]["difference"]["hfr"] == pytest.approx(0.4)
    assert out[0]["direction"]["hfr"] == "holds" and out[0]["direction"]["agreement"] == "holds"
    # b → c: |ΔSR| falls from 25 points to 0: better, so "holds" although the difference is negative.
    assert out[1]["difference"]["abs_delta_sr"] == pytest.approx(-0.25)
    assert out[1]["direction"]["abs_delta_sr"] == "holds"
    assert steps({"a": worst}, ["a", "b"]) == []
