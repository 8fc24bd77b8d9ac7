"""``pilworld bench stability``: the probes' chunk transforms, the shifted head camera, the horizon sweep (on
a synthetic paired set with known figures and on a real 2-round paired run judged by the image-only judge),
the probes' summary on hand-made records, and one end-to-end probe from one start.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from numpy.typing import NDArray

from hw_drivers.safety import SafetyLimits
from pilworld.bench.charts import stability_chart
from pilworld.bench.stability import (
    CAL_SHIFTS_PX,
    HORIZONS,
    JITTER_RAD,
    _fast,
    _hold,
    _jitter,
    _mse,
    _offset,
    _psnr,
    _reverse,
    _summarize_probes,
    horizon_sweep,
    probe,
    shifted_camera,
)
from pilworld.config.rig import RigConfig
from pilworld.data.outcomes import Outcome, read_outcomes, record_outcomes
from pilworld.data.reader import EpisodeStore
from pilworld.judges.base import judge_dataset
from pilworld.judges.vision import VisionJudge
from pilworld.metrics.pairs import load_pairs
from pilworld.paired import PairedConfig, paired_run
from pilworld.types import ChunkSpec
from tests.pilworld.metrics.synthetic import ROUNDS, K, SynthPair, write_paired

SIM = "configs/rig/sim_dual_ur5e.yaml"
PNG = b"\x89PNG\r\n\x1a\n"
GRIPS = [6, 13]
ARMS = [0, 1, 2, 3, 4, 5, 7, 8, 9, 10, 11, 12]
H = ChunkSpec().horizon  # rows of a policy chunk
K_SIM = ChunkSpec().frames
VIEWS = ["cam_high", "cam_left_wrist", "cam_right_wrist"]


def _chunk(seed: int = 0) -> tuple[NDArray[np.float32], NDArray[np.float32]]:
    """A policy-like chunk (a smooth drift away from the state) and the state; grippers differ from the state's."""
    rng = np.random.default_rng(seed)
    state = rng.uniform(-1.0, 1.0, size=14).astype(np.float32)
    state[GRIPS] = 0.2
    drift = rng.uniform(-0.01, 0.01, size=14).astype(np.float32)
    base = (state[None] + np.arange(1, H + 1, dtype=np.float32)[:, None] * drift[None]).astype(np.float32)
    base[:, GRIPS] = np.linspace(0.3, 0.9, H, dtype=np.float32)[:, None]
    return base, state


def _psnr_ref(a: NDArray[np.uint8], b: NDArray[np.uint8]) -> float:
    mse = float(np.mean((a.astype(np.float64) - b.astype(np.float64)) ** 2))
    return 100.0 if mse == 0 else 20.0 * math.log10(255.0) - 10.0 * math.log10(mse)


# ---------------------------------------------------------------------- chunk transforms


@pytest.mark.parametrize("transform", [_hold, _reverse, _fast, _offset])
def test_transforms_keep_the_policy_grippers_and_do_not_touch_the_chunk(
    transform: Callable[[NDArray[np.float32], NDArray[np.float32]], NDArray[np.float32]],
) -> None:
    base, state = _chunk()
    before = base.copy()
    out = transform(base, state)
    assert out.shape == base.shape and out.dtype == np.float32
    np.testing.assert_array_equal(out[:, GRIPS], base[:, GRIPS])
    np.testing.assert_array_equal(base, before)
    assert not np.array_equal(out[:, ARMS], base[:, ARMS])  # the arms' motion does change


def test_hold_reverse_fast_arm_motion() -> None:
    """hold: the state on every row; reverse: the displacement mirrored about the state; fast: ×3."""
    base, state = _chunk()
    disp = base[:, ARMS] - state[None, ARMS]
    np.testing.assert_array_equal(_hold(base, state)[:, ARMS], np.repeat(state[None, ARMS], H, axis=0))
    np.testing.assert_allclose(_reverse(base, state)[:, ARMS] - state[None, ARMS], -disp, atol=1e-6)
    fast = _fast(base, state)[:, ARMS]
    np.testing.assert_allclose(fast - state[None, ARMS], 3.0 * disp, atol=1e-6)  # small steps: exactly ×3
    big = base.copy()
    big[:, ARMS] = state[None, ARMS] + 0.2 * np.arange(1, H + 1, dtype=np.float32)[:, None]
    steps = np.diff(np.vstack([state[None, ARMS], _fast(big, state)[:, ARMS]]), axis=0)
    assert np.abs(steps).max() <= 0.1 + 1e-6  # ×3 of 0.2 rad per step is capped at the joints' top speed


def test_offset_ramps_both_shoulder_lifts_to_0_3_rad() -> None:
    """Columns 1 and 8 get 0.3·min(i/(K·Δ), 1) on row i (0.3 from the last executed row); others the policy's."""
    base, state = _chunk()
    out = _offset(base, state)
    ramp = 0.3 * np.minimum(np.arange(1, H + 1) / ChunkSpec().executed_steps, 1.0)
    for col in (1, 8):
        np.testing.assert_allclose(out[:, col] - base[:, col], ramp, atol=1e-6)
        assert out[-1, col] - base[-1, col] == pytest.approx(0.3, abs=1e-6)
    others = [c for c in range(14) if c not in (1, 8)]
    np.testing.assert_array_equal(out[:, others], base[:, others])
    assert SafetyLimits().max_arm_step > 0.3 / H  # the ramp adds less than the filter's step cap


def test_jitter_stays_under_the_safety_step_cap() -> None:
    """On a constant chunk: arm noise of about JITTER_RAD, at most 2·JITTER_RAD, so consecutive arm targets
    differ by less than the safety filter's cap; grippers untouched; reproducible from the generator."""
    _, state = _chunk()
    base = np.repeat(state[None], H, axis=0).astype(np.float32)
    base[:, GRIPS] = 0.7
    out = _jitter(base, state, np.random.default_rng(0))
    assert out.shape == base.shape and out.dtype == np.float32
    noise = out[:, ARMS] - base[:, ARMS]
    assert np.abs(noise).max() <= 2 * JITTER_RAD + 1e-6
    assert 0.5 * JITTER_RAD < float(noise.std()) < 1.2 * JITTER_RAD
    steps = np.abs(np.diff(out[:, ARMS], axis=0))
    assert steps.max() < SafetyLimits().max_arm_step == 0.35
    np.testing.assert_array_equal(out[:, GRIPS], base[:, GRIPS])
    np.testing.assert_array_equal(out, _jitter(base, state, np.random.default_rng(0)))
    assert not np.array_equal(out, _jitter(base, state, np.random.default_rng(1)))


# ---------------------------------------------------------------------- calibration error


@pytest.mark.parametrize("px", [5.0, 10.0, 20.0])
def test_shifted_camera_moves_projections_by_px(px: float) -> None:
    """The principal point moves px/√2 on both axes, so every projection moves px pixels diagonally."""
    cam = RigConfig.load(SIM).head_camera_model
    K0 = np.array(cam.K, dtype=np.float64).copy()
    shifted = shifted_camera(cam, px)
    d = px / math.sqrt(2.0)
    K1 = np.array(shifted.K, dtype=np.float64)
    assert K1[0, 2] == pytest.approx(K0[0, 2] + d) and K1[1, 2] == pytest.approx(K0[1, 2] + d)
    mask = np.ones((3, 3), dtype=bool)
    mask[0, 2] = mask[1, 2] = False
    np.testing.assert_array_equal(K1[mask], K0[mask])
    np.testing.assert_array_equal(np.array(cam.K), K0)  # the rig's camera is not modified
    np.testing.assert_array_equal(shifted.dist, cam.dist)
    np.testing.assert_array_equal(shifted.T_cam_base, cam.T_cam_base)
    assert (shifted.width, shifted.height, shifted.name) == (cam.width, cam.height, cam.name)

    uv = np.array([[u, v] for u in (32.0, 64.0, 96.0) for v in (40.0, 64.0, 90.0)])
    table, valid = cam.backproject_to_plane(uv, 0.0)
    assert valid.all()
    uv0, vis0 = cam.project(table)
    uv1, _ = shifted.project(table)
    assert vis0.all()
    moved = uv1 - uv0
    np.testing.assert_allclose(np.linalg.norm(moved, axis=1), px, atol=0.05)
    np.testing.assert_allclose(moved, np.full_like(moved, d), atol=0.05)


def test_shift_zero_is_the_same_camera() -> None:
    cam = RigConfig.load(SIM).head_camera_model
    np.testing.assert_array_equal(np.array(shifted_camera(cam, 0.0).K), np.array(cam.K))


# ---------------------------------------------------------------------- horizon sweep, synthetic


def test_horizon_sweep_on_a_synthetic_run(tmp_path: Path) -> None:
    """Exact HFR per horizon from hand-set hallucination frames (checker verdicts and real branches ignored)
    and per-round PSNR at the frame ending each round, beside the start frame held still."""
    root = write_paired(tmp_path / "run", [SynthPair(subtask=0, offset=5), SynthPair(subtask=1, offset=10)])
    T = 1 + ROUNDS * K
    record_outcomes(
        root,
        [
            Outcome(0, "vision", "vision", False, T, 2),  # pair 0 imagined: hallucinates at frame 2
            Outcome(0, "sim_checker", "sim_state", False, T, 1),  # a checker: not part of HFR
            Outcome(1, "vision", "vision", True, T, 1),  # a real branch: not part of HFR
            Outcome(2, "vision", "vision", True, T),  # pair 1 imagined: no hallucination
        ],
    )
    r = horizon_sweep(root, ROUNDS, K)
    assert r["pairs"] == 2 and r["run"] == str(root)
    t1, t2 = 1 + K, 1 + 2 * K
    assert r["rows"] == [
        {"rounds": 1, "frames": t1, "hfr": pytest.approx((2 / t1 + 1.0) / 2), "n": 2},
        {"rounds": 2, "frames": t2, "hfr": pytest.approx((2 / t2 + 1.0) / 2), "n": 2},
    ]
    store = EpisodeStore(root)
    imag = [store.frames(i, "cam_high") for i in (0, 2)]
    real = [store.frames(i, "cam_high") for i in (1, 3)]
    # Round 1 ends on frame K: the imagined frame is the real one + offset (no clipping: real pixels 40..199).
    assert r["per_round"][0]["psnr_head"] == pytest.approx((20 * math.log10(255 / 5) + 20 * math.log10(255 / 10)) / 2)
    for row, rnd in zip(r["per_round"], (1, 2), strict=True):
        k = rnd * K
        assert row["round"] == rnd and row["n"] == 2
        assert row["psnr_head"] == pytest.approx(
            np.mean([_psnr_ref(i[k], re[k]) for i, re in zip(imag, real, strict=True)])
        )
        assert row["psnr_head_frozen"] == pytest.approx(np.mean([_psnr_ref(re[0], re[k]) for re in real]))
    assert len(r["per_round"]) == 2

    # Horizons up to the rounds asked for; rounds beyond the stored frames get no per-round row.
    longer = horizon_sweep(root, 5, K)
    assert [row["rounds"] for row in longer["rows"]] == [h for h in HORIZONS if h <= 5] == [1, 2, 5]
    assert longer["rows"][2]["hfr"] == pytest.approx((2 / (1 + 5 * K) + T / (1 + 5 * K)) / 2)
    assert [row["round"] for row in longer["per_round"]] == [1, 2]
    assert [row["rounds"] for row in horizon_sweep(root, 1, K)["rows"]] == [1]


def test_horizon_sweep_without_verdicts(tmp_path: Path) -> None:
    """An unjudged run has no HFR (None, n = 0) but still its per-round error."""
    root = write_paired(tmp_path / "run", [SynthPair(offset=5)])
    r = horizon_sweep(root, ROUNDS, K)
    assert [(row["hfr"], row["n"]) for row in r["rows"]] == [(None, 0), (None, 0)]
    assert [row["n"] for row in r["per_round"]] == [1, 1]


# ---------------------------------------------------------------------- horizon sweep, real run


@pytest.fixture(scope="module")
def judged_run(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A 2-round paired run (sort_cubes, scripted_step_30k, 1 subtask) judged by the image-only judge."""
    out = tmp_path_factory.mktemp("stability") / "run"
    cfg = PairedConfig(
        rig=SIM,
        task="sort_cubes",
        checkpoints=["scripted_step_30k"],
        subtasks=1,
        out=str(out),
        spec=ChunkSpec(rounds=2),
    )
    paired_run(cfg, progress=False)
    judge_dataset(out, [VisionJudge()], RigConfig.load(SIM), workers=1)
    return out


def test_horizon_sweep_on_a_real_run(judged_run: Path) -> None:
    """HFR rows for horizons 1 and 2 only, in [0, 1], from the imagined branch's vision verdict; per-round
    PSNR finite for rounds 1 and 2."""
    r = horizon_sweep(judged_run, 2, K_SIM)
    assert r["pairs"] == 1 and r["run"] == str(judged_run)
    assert [(row["rounds"], row["frames"], row["n"]) for row in r["rows"]] == [(1, 1 + K_SIM, 1), (2, 1 + 2 * K_SIM, 1)]
    (pair,) = load_pairs(judged_run).pairs
    (verdict,) = [o for o in read_outcomes(judged_run) if o.episode_index == pair.imagined and o.judge_id == "vision"]
    t_h = verdict.num_frames if verdict.first_hallucination_frame is None else verdict.first_hallucination_frame
    for row in r["rows"]:
        assert 0.0 <= row["hfr"] <= 1.0
        assert row["hfr"] == pytest.approx(min(t_h, row["frames"]) / row["frames"])
    assert [row["round"] for row in r["per_round"]] == [1, 2]
    for row in r["per_round"]:
        assert row["n"] == 1
        assert math.isfinite(row["psnr_head"]) and math.isfinite(row["psnr_head_frozen"])
        assert 5.0 < row["psnr_head"] <= 100.0
    assert [row["rounds"] for row in horizon_sweep(judged_run, 1, K_SIM)["rows"]] == [1]


# ---------------------------------------------------------------------- probe summaries


def _views(high: float, left: float) -> dict[str, float]:
    return {"cam_high": high, "cam_left_wrist": left}


def _div(high: tuple[float, float], left: tuple[float, float]) -> dict[str, dict[str, float]]:
    return {
        "cam_high": {"pred": high[0], "real": high[1]},
        "cam_left_wrist": {"pred": left[0], "real": left[1]},
    }


def _record(
    i: int, hold: tuple[tuple[float, float], tuple[float, float]], policy: float, kinds: tuple[str, ...]
) -> dict[str, Any]:
    rec: dict[str, Any] = {
        "pair": f"p{i}",
        "task": "sort_cubes",
        "div:hold": _div(*hold),
        "div:reverse": _div((1.0 + i, 2.0), (float(i), 0.0)),  # the left view never differs in reality
        "psnr:policy": _views(policy, policy + 10),
        "psnr:policy@5px": _views(policy - 1, 0.0),
        "psnr:policy@10px": _views(policy - 3, 0.0),
        "psnr:policy@20px": _views(policy - 6, 0.0),
        "psnr:frozen": _views(20.0 + i, 30.0),
    }
    for n, kind in enumerate(kinds):
        rec[f"psnr:{kind}"] = _views(policy - 2 - n, policy)
    return rec


def test_summarize_probes_on_hand_made_records() -> None:
    """Counterfactual ratio = median of per-start pred/real (starts with no real difference skipped), the
    calibration delta relative to shift 0, OOD rows over the starts that ran the kind."""
    records = [
        _record(0, ((2.0, 4.0), (0.0, 0.0)), 30.0, ("fast", "jitter")),  # offset refused here
        _record(1, ((4.0, 1.0), (0.0, 2.0)), 32.0, ("fast", "jitter")),
        _record(2, ((1.0, 1.0), (6.0, 2.0)), 34.0, ("jitter",)),  # fast refused here
    ]
    s = _summarize_probes(records, ["cam_high", "cam_left_wrist"])
    assert s["starts"] == 3

    hold, reverse = s["counterfactual"]["rows"]
    assert hold["alternative"] == "hold" and reverse["alternative"] == "reverse"
    # Ratios 0.5, 4, 1: median 1 (not their mean 1.83, nor the ratio of means 7/6).
    assert hold["cam_high"] == {
        "mse_pred": pytest.approx(7 / 3),
        "mse_real": pytest.approx(2.0),
        "ratio_median": pytest.approx(1.0),
        "distinct_share": 1.0,
    }
    # Start 0 has no real difference: ratios 0 and 3 only; 1 of 3 predictions differs at all.
    assert hold["cam_left_wrist"]["ratio_median"] == pytest.approx(1.5)
    assert hold["cam_left_wrist"]["distinct_share"] == pytest.approx(1 / 3)
    assert reverse["cam_high"]["ratio_median"] == pytest.approx(1.0)  # 1/2, 2/2, 3/2
    assert reverse["cam_left_wrist"]["ratio_median"] is None  # never a real difference
    assert reverse["cam_left_wrist"]["mse_real"] == 0.0 and reverse["cam_left_wrist"][
        "distinct_share"
    ] == pytest.approx(2 / 3)

    cal = s["calibration"]["rows"]
    assert [row["shift_px"] for row in cal] == list(CAL_SHIFTS_PX) == [0.0, 5.0, 10.0, 20.0]
    assert [row["psnr_head"] for row in cal] == pytest.approx([32.0, 31.0, 29.0, 26.0])
    assert [row["delta_db"] for row in cal] == pytest.approx([0.0, -1.0, -3.0, -6.0])
    assert [row["n"] for row in cal] == [3, 3, 3, 3]

    ood = {row["kind"]: row for row in s["ood_actions"]["rows"]}
    assert list(ood) == ["policy", "fast", "jitter", "offset"]
    assert [ood[k]["n"] for k in ood] == [3, 2, 3, 0]
    assert ood["policy"]["psnr_head"] == pytest.approx(32.0)
    assert ood["policy"]["per_view"] == {"cam_high": pytest.approx(32.0), "cam_left_wrist": pytest.approx(42.0)}
    assert ood["fast"]["psnr_head"] == pytest.approx(29.0)  # starts 0 and 1: 28, 30
    assert ood["jitter"]["psnr_head"] == pytest.approx(np.mean([27.0, 29.0, 32.0]))
    assert ood["offset"]["psnr_head"] is None and ood["offset"]["per_view"] == {
        "cam_high": None,
        "cam_left_wrist": None,
    }
    assert s["ood_actions"]["frozen_per_view"] == {
        "cam_high": pytest.approx(21.0),
        "cam_left_wrist": pytest.approx(30.0),
    }


def test_summarize_no_probe_records() -> None:
    """No start finished: every figure is None, counts 0."""
    s = _summarize_probes([], ["cam_high"])
    assert s["starts"] == 0
    for row in s["counterfactual"]["rows"]:
        assert row["cam_high"] == {"mse_pred": None, "mse_real": None, "ratio_median": None, "distinct_share": None}
    assert all(
        row["psnr_head"] is None and row["delta_db"] is None and row["n"] == 0 for row in s["calibration"]["rows"]
    )
    assert all(row["psnr_head"] is None and row["n"] == 0 for row in s["ood_actions"]["rows"])


def test_psnr_and_mse() -> None:
    a = np.full((2, 4, 4, 3), 100, dtype=np.uint8)
    b = a + np.uint8(5)
    assert _mse(a, b) == 25.0 and _mse(b, a) == 25.0 and _mse(a, a) == 0.0
    assert _psnr(a, b) == pytest.approx(10 * math.log10(255.0**2 / 25.0))
    assert _psnr(a, a) == 100.0


# ---------------------------------------------------------------------- one probe end to end


@pytest.fixture(scope="module")
def probed() -> dict[str, Any]:
    """The probes from one start (sort_cubes, scripted_step_30k)."""
    return probe(rig=SIM, tasks=("sort_cubes",), checkpoints=("scripted_step_30k",), starts=1, progress=False)


def test_probe_counterfactual_and_calibration(probed: dict[str, Any]) -> None:
    assert probed["starts"] == 1
    rows = probed["counterfactual"]["rows"]
    assert [row["alternative"] for row in rows] == ["hold", "reverse"]
    for row in rows:
        assert set(row) == {"alternative", *VIEWS}
        for v in VIEWS:
            fig = row[v]
            assert set(fig) == {"mse_pred", "mse_real", "ratio_median", "distinct_share"}, v
            assert fig["mse_pred"] >= 0.0 and fig["mse_real"] >= 0.0, v
        # The policy moves the arms, hold and reverse do not: the head camera sees different futures.
        assert row["cam_high"]["mse_real"] > 0.0 and row["cam_high"]["ratio_median"] >= 0.0
    cal = probed["calibration"]["rows"]
    assert [row["shift_px"] for row in cal] == [0.0, 5.0, 10.0, 20.0]
    assert cal[0]["delta_db"] == 0.0
    for row in cal:
        assert row["n"] == 1 and math.isfinite(row["psnr_head"]) and math.isfinite(row["delta_db"])


def test_probe_ood_actions_and_refusals(probed: dict[str, Any]) -> None:
    """Every OOD kind has a row; a kind the safety filter refused is listed in ``refused`` and has no PSNR."""
    ood = probed["ood_actions"]["rows"]
    assert [row["kind"] for row in ood] == ["policy", "fast", "jitter", "offset"]
    refused = probed["refused"]
    assert isinstance(refused, list)
    for item in refused:
        assert set(item) == {"pair", "kind", "error"}
        assert item["pair"] == "sort_cubes/scripted_step_30k/seed7000000/subtask0"
        assert item["kind"] in ("fast", "jitter", "offset")  # the start counted: policy, hold, reverse ran
    refused_kinds = {item["kind"] for item in refused}
    for row in ood:
        assert set(row["per_view"]) == set(VIEWS)
        if row["kind"] in refused_kinds:
            assert row["n"] == 0 and row["psnr_head"] is None, row["kind"]
        else:
            assert row["n"] == 1 and math.isfinite(row["psnr_head"]), row["kind"]
            assert row["psnr_head"] == row["per_view"]["cam_high"]
    # The policy's chunk without a calibration error is the same prediction in both tables.
    assert ood[0]["psnr_head"] == probed["calibration"]["rows"][0]["psnr_head"]
    assert set(probed["ood_actions"]["frozen_per_view"]) == set(VIEWS)


def test_stability_chart_from_the_probe_and_sweep(probed: dict[str, Any], judged_run: Path, tmp_path: Path) -> None:
    """The bench's chart draws from these results (including a None PSNR of a refused kind)."""
    result = {"horizon": horizon_sweep(judged_run, 2, K_SIM), **probed}
    path = stability_chart(result, tmp_path / "sub" / "stability.png")
    assert path == tmp_path / "sub" / "stability.png" and path.read_bytes()[:8] == PNG
