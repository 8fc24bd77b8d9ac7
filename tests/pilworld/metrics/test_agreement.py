"""Agreement statistics against hand-computed values."""

from __future__ import annotations

from pathlib import Path

import pytest

from pilworld.data.outcomes import Outcome
from pilworld.data.pairs import Pair, PairedEpisodes
from pilworld.metrics.agreement import NO_SHARED, ONE_CATEGORY, cohen_kappa, fleiss_kappa, human_agreement, mad

# Wikipedia, "Fleiss' kappa", worked example: 10 subjects, 14 raters, 5 categories.
WIKIPEDIA = [
    [0, 0, 0, 0, 14],
    [0, 2, 6, 4, 2],
    [0, 0, 3, 5, 6],
    [0, 3, 9, 2, 0],
    [2, 2, 8, 1, 1],
    [7, 7, 0, 0, 0],
    [3, 2, 6, 3, 0],
    [2, 5, 3, 2, 2],
    [6, 5, 2, 1, 0],
    [0, 2, 2, 3, 7],
]


def test_fleiss_wikipedia_example() -> None:
    kappa, reason, stats = fleiss_kappa(WIKIPEDIA)
    assert reason is None
    assert kappa == pytest.approx(0.210, abs=5e-4)
    assert stats["observed"] == pytest.approx(0.378, abs=5e-4)
    assert stats["chance"] == pytest.approx(0.213, abs=5e-4)


def test_fleiss_with_unequal_raters() -> None:
    # P_i = 1, 0, 1/3 → P̄ = 4/9; p = (5/7, 2/7) → P_e = 29/49; κ = (4/9 − 29/49) / (20/49) = −13/36
    kappa, _, _ = fleiss_kappa([[2, 0], [1, 1], [2, 1]])
    assert kappa == pytest.approx(-13 / 36)


def test_fleiss_degenerate_cases() -> None:
    assert fleiss_kappa([[3, 0], [2, 0]])[:2] == (None, ONE_CATEGORY)
    assert fleiss_kappa([])[:2] == (None, NO_SHARED)
    assert fleiss_kappa([[2, 0], [0, 2]])[0] == pytest.approx(1.0)
    with pytest.raises(ValueError, match="two or more"):
        fleiss_kappa([[1, 0]])


def test_cohen_and_mad() -> None:
    assert cohen_kappa([True, True, False, False], [True, False, False, False])[0] == pytest.approx(0.5)
    assert cohen_kappa([True, True], [True, True]) == (None, ONE_CATEGORY)
    assert cohen_kappa([], [])[0] is None
    assert mad([1, 2, 3, 4, 100]) == 1.0


T = 10
# episode → {judge: (success, first hallucination frame)}; episodes 0, 2 imagined, 1, 3 real
LABELS: dict[int, dict[str, tuple[bool, int | None]]] = {
    0: {"human_1": (True, 3), "human_2": (True, 5), "human_3": (False, None), "vision": (True, 4)},
    1: {"human_1": (True, None), "human_2": (True, None), "human_3": (True, None), "vision": (True, None)},
    2: {"human_1": (False, 2), "human_2": (False, 4), "human_3": (False, 9), "vision": (True, 2)},
    3: {"human_1": (True, None), "human_2": (False, None), "human_3": (False, 7), "vision": (False, None)},
}
ORIGINS = {0: "imagined", 1: "real", 2: "imagined", 3: "real"}


def _paired() -> PairedEpisodes:
    verdicts: dict[int, list[Outcome]] = {}
    for e, by_judge in LABELS.items():
        rows = [
            Outcome(e, j, "vision" if j == "vision" else "human", s, T, first_hallucination_frame=f)
            for j, (s, f) in by_judge.items()
        ]
        if ORIGINS[e] == "real":
            rows.append(Outcome(e, "sim_checker", "sim_state", True, T))
        verdicts[e] = rows
    pairs = [Pair("p0", "t", "c", imagined=0, real=1), Pair("p1", "t", "c", imagined=2, real=3)]
    return PairedEpisodes(root=Path(), pairs=pairs, verdicts=verdicts)


def test_human_agreement_by_hand() -> None:
    a = human_agreement(_paired(), ORIGINS, bootstrap=0)
    assert a["judges"] == ["human_1", "human_2", "human_3"]
    assert a["episodes_shared"] == 4
    # success counts [2,1] [3,0] [0,3] [1,2]: P̄ = 2/3, P_e = 1/2 → κ = 1/3
    s = a["success"]
    assert s["fleiss_kappa"] == pytest.approx(1 / 3) and s["unanimous_share"] == 0.5
    assert s["raters_per_episode"] == {"min": 3, "max": 3}
    h = a["hallucination"]["all"]
    assert (h["agree_none_share"], h["agree_some_share"]) == (0.25, 0.25)
    assert h["presence_fleiss_kappa"] == pytest.approx(1 / 3)
    # frames [3, 5] → MAD 1, range 2; [2, 4, 9] → MAD 2, range 7
    assert h["frame_spread"] == {
        "episodes": 2,
        "mad_median": 1.5,
        "mad_mean": 1.5,
        "range_median": 4.5,
        "range_mean": 4.5,
        "range_max": 7.0,
    }
    assert a["hallucination"]["real"]["agree_none_share"] == 0.5
    assert a["hallucination"]["real"]["frame_spread"]["episodes"] == 0
    assert a["hallucination"]["imagined"]["agree_some_share"] == 0.5

    v = a["vs_other_judges"]["human_1"]["vision"]
    assert v["episodes"] == 4 and v["success_agreement"] == 0.5
    assert v["success_cohen_kappa"] == pytest.approx(-1 / 3)
    assert v["hallucination_presence_agreement"] == 1.0
    assert (v["frame_pairs"], v["frame_abs_diff_median"]) == (2, 0.5)
    c = a["vs_other_judges"]["human_1"]["sim_checker"]
    assert c["episodes"] == 2 and c["success_agreement"] == 1.0  # real episodes only
    assert c["success_cohen_kappa"] is None and c["success_cohen_kappa_reason"] == ONE_CATEGORY
    assert "hallucination_presence_agreement" not in c

    # human judges alone: SR_real = (1 + 1/3) / 2, SR_imag = (2/3 + 0) / 2, HFR = (0.6 + 0.5) / 2
    o = a["human_only"]["overall"]
    assert o["sr_real"] == pytest.approx(2 / 3) and o["sr_imag"] == pytest.approx(1 / 3)
    assert o["abs_delta_sr"] == pytest.approx(1 / 3) and o["hfr"] == pytest.approx(0.55)
    assert "sr_real_checker" not in o


def test_without_human_verdicts() -> None:
    paired = _paired()
    paired.verdicts = {e: [o for o in v if not o.judge_id.startswith("human")] for e, v in paired.verdicts.items()}
    a = human_agreement(paired, ORIGINS)
    assert a["judges"] == [] and "reason" in a


def test_one_human_has_no_between_judge_statistics() -> None:
    paired = _paired()
    keep = {"human_1", "vision", "sim_checker"}
    paired.verdicts = {e: [o for o in v if o.judge_id in keep] for e, v in paired.verdicts.items()}
    a = human_agreement(paired, ORIGINS, bootstrap=0)
    assert a["episodes_shared"] == 0
    assert a["success"]["fleiss_kappa"] is None and a["success"]["fleiss_kappa_reason"] == NO_SHARED
    assert a["hallucination"]["all"]["reason"] == NO_SHARED
    assert a["vs_other_judges"]["human_1"]["vision"]["episodes"] == 4
