"""SR over the judges of both branches, |ΔSR|, HFR and the checker's rate, on hand-computed verdicts."""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

import pytest

from pilworld.data.outcomes import Outcome
from pilworld.data.pairs import Pair, PairedEpisodes
from pilworld.metrics.success import NO_COMMON_JUDGE, group_metrics, judge_summary, score_pairs

T = 10  # frames per episode
Row = tuple[int, str, str, bool, int | None]  # (episode, judge, kind, success, first hallucination frame)


def _paired(n: int, verdicts: Sequence[Row]) -> PairedEpisodes:
    """``n`` pairs (imagined episode 2i, real 2i+1); verdicts (episode, judge, kind, success, t_h)."""
    pairs = [Pair(f"t/c/seed0/subtask{i}", "t", "c", imagined=2 * i, real=2 * i + 1) for i in range(n)]
    table: dict[int, list[Outcome]] = {}
    for ep, judge, kind, ok, t_h in verdicts:
        table.setdefault(ep, []).append(Outcome(ep, judge, kind, ok, T, t_h))
    return PairedEpisodes(root=Path(), pairs=pairs, verdicts=table)


def _branch(judge: str, kind: str, real: list[int], imag: list[int], t_h: list[int | None] | None = None) -> list[Row]:
    out: list[Row] = [(2 * i + 1, judge, kind, bool(y), None) for i, y in enumerate(real)]
    frames = t_h or [None] * len(imag)
    return out + [(2 * i, judge, kind, bool(y), f) for i, (y, f) in enumerate(zip(imag, frames, strict=True))]


def test_sr_is_the_papers_mean_over_m_judges_when_all_judged_everything() -> None:
    verdicts = _branch("A", "vision", [1, 1, 0], [1, 0, 0]) + _branch("B", "human", [1, 0, 0], [1, 1, 0])
    verdicts += [(2 * i + 1, "sim_checker", "sim_state", y, None) for i, y in enumerate([True, True, False])]
    m = group_metrics(score_pairs(_paired(3, verdicts)), bootstrap=0)
    # Paper: SR_real = (1/M) Σ_m (1/N) Σ_i y = (2/3 + 1/3) / 2; SR_imag = (1/3 + 2/3) / 2.
    assert m["sr_real"] == pytest.approx(0.5) and m["sr_imag"] == pytest.approx(0.5)
    assert m["abs_delta_sr"] == pytest.approx(0.0)
    assert m["sr_real_checker"] == pytest.approx(2 / 3)  # never part of SR_real: it saw no imagined episode
    assert (m["n_subtasks"], m["n_judged"], m["n_checker"]) == (3, 3, 3)
    assert m["ci95"] is None


def test_partial_coverage_weights_each_pair_once() -> None:
    verdicts = _branch("A", "vision", [1, 1, 0], [1, 0, 0]) + _branch("B", "vision", [1, 0, 0], [1, 1, 0])
    verdicts += [(1, "C", "human", False, None), (0, "C", "human", True, None)]  # C judged pair 0 only
    verdicts += [(2, "D", "human", True, 4)]  # D judged one imagined episode: no SR, but a hallucination verdict
    paired = _paired(3, verdicts)
    scores = score_pairs(paired)
    assert scores[0].judges == ("A", "B", "C") and scores[1].judges == ("A", "B")
    m = group_metrics(scores, bootstrap=0)
    # Pair 0: real (1+1+0)/3, imag (1+1+1)/3; pair 1: .5, .5; pair 2: 0, 0.
    assert m["sr_real"] == pytest.approx((2 / 3 + 0.5 + 0) / 3)
    assert m["sr_imag"] == pytest.approx((1 + 0.5 + 0) / 3)
    assert m["abs_delta_sr"] == pytest.approx(1 / 9) and m["delta_sr"] == pytest.approx(1 / 9)
    summary = judge_summary(paired, scores)
    assert summary["success"] == ["A", "B", "C"] and summary["hallucination"] == ["A", "B", "C", "D"]
    assert summary["per_judge"]["D"]["imagined_only"] == 1 and summary["per_judge"]["D"]["pairs_both"] == 0
    assert summary["per_judge"]["C"]["sr_real"] == 0.0 and summary["per_judge"]["C"]["sr_imag"] == 1.0


def test_hfr_with_and_without_hallucination_frames() -> None:
    none_seen = _branch("A", "vision", [1, 1], [1, 1])
    assert group_metrics(score_pairs(_paired(2, none_seen)), bootstrap=0)["hfr"] == 1.0  # t_h = T everywhere
    verdicts = _branch("A", "vision", [1, 1, 0], [1, 0, 0], t_h=[None, 5, None])
    verdicts += _branch("B", "human", [1, 0, 0], [1, 1, 0], t_h=[2, None, None])
    m = group_metrics(score_pairs(_paired(3, verdicts)), bootstrap=0)
    # Paper: (1/M) Σ_m (1/N) Σ_i t_h/T = ((1 + .5 + 1)/3 + (.2 + 1 + 1)/3) / 2.
    assert m["hfr"] == pytest.approx(((1 + 0.5 + 1) / 3 + (0.2 + 1 + 1) / 3) / 2)
    assert m["n_hfr"] == 3


def test_checker_alone_gives_no_sr_and_says_why() -> None:
    verdicts: list[Row] = [(1, "sim_checker", "sim_state", True, None), (3, "sim_checker", "sim_state", False, None)]
    paired = _paired(2, verdicts)
    m = group_metrics(score_pairs(paired), bootstrap=100)
    assert m["sr_real"] is None and m["sr_imag"] is None and m["abs_delta_sr"] is None and m["hfr"] is None
    assert m["sr_real_reason"] == NO_COMMON_JUDGE and "imagined" in m["hfr_reason"]
    assert m["sr_real_checker"] == 0.5
    assert m["ci95"]["sr_real"] is None and m["ci95"]["sr_real_checker"] is not None
    assert judge_summary(paired, score_pairs(paired))["pairs_without_common_judge"] == 2


def test_agreement_with_the_checker() -> None:
    verdicts = _branch("A", "vision", [1, 0, 1, 1], [1, 0, 0, 0])
    verdicts += [(2 * i + 1, "sim_checker", "sim_state", y, None) for i, y in enumerate([True, False, False, False])]
    paired = _paired(4, verdicts)
    per = judge_summary(paired, score_pairs(paired))["per_judge"]
    assert per["A"]["agreement_with_checker"] == pytest.approx(0.5)
    assert per["A"]["episodes_compared_with_checker"] == 4
    assert per["sim_checker"]["agreement_with_checker"] is None and per["sim_checker"]["real_only"] == 4
