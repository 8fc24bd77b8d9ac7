"""``pilworld bench speed-accuracy``: the closed-loop front, the knee (the smallest model that reaches the
accuracy), the old single-step knee, what each step buys, model loading (v1, v2, missing v2 sizes), the
closed-loop wiring (evaluate_variants monkeypatched), a whole sweep on fake models (every stage's wiring), one
small real sweep (v1 tiny, v2 shipped, an untrained tiny, a missing v2 size; closed loop off) with its chart,
and the CLI's argument errors.
"""

from __future__ import annotations

import json
import math
from collections.abc import Iterator
from pathlib import Path
from types import SimpleNamespace
from typing import Any

import pytest
import torch

import pilworld.bench.chunk_latency as cl
import pilworld.bench.speed_accuracy as sa
import pilworld.bench.world_model as wm
from pilworld.bench.charts import speed_accuracy_chart
from pilworld.bench.paired import QUICK_CHECKPOINTS, protocol
from pilworld.bench.results_tables import speed_accuracy_tables
from pilworld.bench.speed_accuracy import (
    CLOSED_LOOP_SUBTASKS,
    STEPS,
    TrainedModel,
    _closed_loop,
    _load,
    closed_loop_steps,
    default_models,
    parameter_count,
    run_speed_accuracy,
)
from pilworld.bench.speed_accuracy_front import (
    KNEE_DB,
    KNEE_HFR,
    SHIPPED,
    SINGLE_STEP_OBJECTIVES,
    choose_knee,
    choose_single_step_default,
    knee_tolerances,
    pareto_front,
    shipped_verdict,
    size_buy,
    steps_buy,
)
from pilworld.bench.variants import BENCH_WEIGHTS, ModelVariant, PairedProtocol
from pilworld.cli.main import main
from pilworld.config.rig import ImageSize, RigConfig
from pilworld.world_model import DEFAULT_CHECKPOINT, V1_CHECKPOINT
from pilworld.world_model.composite.checkpoint import save_composite
from pilworld.world_model.composite.model import CompositeConfig, CompositeWorldModel
from pilworld.world_model.latent.model import PilWorldModel
from pilworld.world_model.resized import ResizedWorldModel
from simrig.tasks import TASK_NAMES

SIM = "configs/rig/sim_dual_ur5e.yaml"
PNG = b"\x89PNG\r\n\x1a\n"
HELDOUT_TASK = "stack_blocks"  # 2 subtasks: the cheapest task to collect whole
PAIRS = 18


def _pt(
    pid: str,
    latency: float,
    dsr: float | None,
    hfr: float | None,
    *,
    params: int = 1000,
    rt: float = 2.0,
    psnr: float | None = 20.0,
    family: str = "v1",
    model: str | None = None,
    steps: int = 1,
    **extra: Any,
) -> dict[str, Any]:
    return {
        "id": pid,
        "model": model or pid,
        "family": family,
        "preset": "v2" if family == "v2" else "small",
        "size": "128x128",
        "steps": steps,
        "params": params,
        "chunk_latency_ms": latency,
        "realtime_factor": rt,
        "abs_delta_sr": dsr,
        "hfr": hfr,
        "sr_imag": None if dsr is None else 0.5,
        "psnr_head": psnr,
        **extra,
    }


# ---------------------------------------------------------------------- the front


def test_closed_loop_front_is_non_dominated_on_latency_dsr_and_hfr() -> None:
    """A point stays unless another is no slower, no worse on |ΔSR| and HFR, and better on one; points without
    closed-loop figures, untrained and skipped points take no part (not even as dominators)."""
    points = [
        _pt("e", 50.0, 0.0, 0.95),  # best HFR
        _pt("b", 20.0, 0.05, 0.9),
        _pt("c", 30.0, 0.05, 0.8),  # slower than b, as good on |ΔSR|, worse HFR
        _pt("a", 10.0, 0.5, 0.1),  # fastest
        _pt("d", 40.0, 0.0, 0.85),  # best |ΔSR| at lower latency than e
        _pt("f", 5.0, None, None),  # not run in closed loop
        _pt("g", 1.0, 0.0, 1.0, untrained="random weights"),
        _pt("h", 1.0, 0.0, 1.0, skipped="not trained: scripts/train-bench-variants h"),
        _pt("i", 40.0, 0.0, 0.85),  # identical to d: neither beats the other
        _pt("j", 60.0, 0.0, 0.95),  # as good as e, slower
    ]
    assert pareto_front(points) == ["a", "b", "d", "i", "e"]
    assert pareto_front([p for p in points if p["id"] != "b"]) == ["a", "c", "d", "i", "e"]  # c no longer beaten
    assert pareto_front([]) == [] and pareto_front([_pt("x", 1.0, None, None)]) == []


def test_single_step_front_uses_latency_and_psnr_only() -> None:
    points = [
        _pt("a", 10.0, 0.5, 0.1, psnr=20.0),
        _pt("b", 20.0, 0.0, 1.0, psnr=19.0),  # best in closed loop, dominated on PSNR
        _pt("c", 30.0, None, None, psnr=21.0),  # no closed loop: still on the single-step front
        _pt("d", 5.0, None, None, psnr=None),
    ]
    assert pareto_front(points, SINGLE_STEP_OBJECTIVES) == ["a", "c"]
    assert pareto_front(points) == ["a", "b"]


# ---------------------------------------------------------------------- the knee


def _knee_points() -> list[dict[str, Any]]:
    tol = 1.0 / PAIRS
    return [
        _pt("big", 60.0, 0.0, 0.95, params=8_700_000),  # the best on both
        _pt("v2", 160.0, tol, 0.95 - KNEE_HFR, params=90_000, family="v2"),  # within both tolerances: the knee
        _pt("tiny_bad", 10.0, 0.5, 0.1, params=30_000),  # fewer parameters, not accurate
        _pt("dsr_out", 100.0, tol + 0.001, 0.95, params=20_000),  # just outside the |ΔSR| tolerance
        _pt("hfr_out", 100.0, 0.0, 0.95 - KNEE_HFR - 0.001, params=20_000),  # just outside the HFR tolerance
        _pt("slow", 2000.0, 0.0, 0.95, params=10_000, rt=0.75),  # accurate and small, not real time
        _pt("untrained", 1.0, 0.0, 1.0, params=1, untrained="random weights"),
        _pt("skipped", 1.0, 0.0, 1.0, params=1, skipped="not trained"),
        _pt("unrun", 1.0, None, None, params=1),
    ]


def test_knee_is_the_smallest_real_time_model_within_both_tolerances() -> None:
    points = _knee_points()
    front = pareto_front(points)
    d = choose_knee(points, front, pairs=PAIRS)
    assert d["id"] == "v2"
    assert (d["best_id"], d["best_abs_delta_sr"], d["best_hfr"]) == ("big", 0.0, 1.0 - 0.05)
    assert d["tolerances"] == knee_tolerances(PAIRS) and d["pairs"] == PAIRS
    assert d["reaching"] == ["big", "slow", "v2"]
    assert (d["params"], d["chunk_latency_ms"], d["family"]) == (90_000, 160.0, "v2")
    assert d["on_front"] == ("v2" in front)
    assert "fewest parameters" in d["rule"] and "real-time" in d["rule"]
    # Without v2, the next smallest reaching real-time point is the big one (not the faster inaccurate ones).
    assert choose_knee([p for p in points if p["id"] != "v2"], front, pairs=PAIRS)["id"] == "big"


def test_knee_ties_on_parameters_go_to_the_faster_point() -> None:
    """One model at several step counts has one parameter count: the fastest reaching step count wins."""
    points = [
        _pt("tiny_s4", 30.0, 0.0, 0.9, params=300_000, model="tiny", steps=4),
        _pt("tiny_s1", 10.0, 0.02, 0.88, params=300_000, model="tiny", steps=1),
        _pt("small_s1", 5.0, 0.0, 0.9, params=8_000_000, model="small"),
    ]
    assert choose_knee(points, pareto_front(points), pairs=PAIRS)["id"] == "tiny_s1"


def test_knee_tolerances_follow_the_protocol_size() -> None:
    """One pair is 1/N of SR: the |ΔSR| tolerance is max(0.05, 1/N); HFR's is fixed."""
    assert knee_tolerances(18) == {"abs_delta_sr": round(1 / 18, 4), "hfr": KNEE_HFR}
    assert knee_tolerances(6)["abs_delta_sr"] == round(1 / 6, 4)
    assert knee_tolerances(300)["abs_delta_sr"] == 0.05
    with pytest.raises(ValueError, match="pairs"):
        knee_tolerances(0)
    # With 6 pairs a point one pair off the best reaches the accuracy; with 18 pairs a point 2 pairs off does not.
    points = [_pt("best", 50.0, 0.0, 0.9, params=10), _pt("small", 60.0, 1 / 6, 0.9, params=5)]
    assert choose_knee(points, [], pairs=6)["id"] == "small"
    points[1]["abs_delta_sr"] = 2 / 18
    assert choose_knee(points, [], pairs=18)["id"] == "best"


def test_knee_fallbacks() -> None:
    """No reaching point keeps real time: the fastest of them. The best |ΔSR| and the best HFR far apart (no point
    reaches both): the |ΔSR| tolerance alone decides. Each fallback is written into the rule."""
    slow = [_pt("a", 3000.0, 0.0, 0.9, params=5, rt=0.5), _pt("b", 2000.0, 0.01, 0.9, params=50, rt=0.75)]
    d = choose_knee(slow, pareto_front(slow), pairs=PAIRS)
    assert d["id"] == "b" and "none of them keeps real time" in d["rule"]
    apart = [_pt("dsr", 50.0, 0.0, 0.5, params=50), _pt("hfr", 50.0, 0.5, 0.95, params=5)]
    d = choose_knee(apart, pareto_front(apart), pairs=PAIRS)
    assert d["id"] == "dsr" and "|ΔSR| tolerance alone" in d["rule"]


def test_knee_without_closed_loop_accuracy_raises() -> None:
    points = [
        _pt("unrun", 10.0, None, None),
        _pt("untrained", 10.0, 0.0, 1.0, untrained="random weights"),
        _pt("skipped", 10.0, 0.0, 1.0, skipped="not trained"),
    ]
    with pytest.raises(ValueError, match="no point has a closed-loop accuracy"):
        choose_knee(points, pareto_front(points), pairs=PAIRS)


def test_single_step_knee_is_the_old_psnr_rule() -> None:
    """Fastest real-time point of the (latency, PSNR) front within KNEE_DB of the best; fastest front point when
    none keeps real time; an error without any PSNR."""
    best = 25.0
    points = [
        _pt("A", 10.0, None, None, psnr=best - 2 * KNEE_DB, rt=4.0),
        _pt("B", 20.0, None, None, psnr=best - KNEE_DB, rt=2.0),  # exactly KNEE_DB below still reaches
        _pt("C", 40.0, None, None, psnr=best, rt=1.0),
    ]
    front = pareto_front(points, SINGLE_STEP_OBJECTIVES)
    d = choose_single_step_default(points, front)
    assert (d["id"], d["best_psnr_head"], d["front_ids"]) == ("B", best, ["A", "B", "C"])
    points[1]["realtime_factor"] = 0.5
    assert choose_single_step_default(points, front)["id"] == "C"
    for p in points:
        p["realtime_factor"] = 0.5
    assert choose_single_step_default(points, front)["id"] == "A"
    with pytest.raises(ValueError, match="no point has a single-step accuracy"):
        choose_single_step_default([_pt("x", 1.0, None, None, psnr=None)], ["x"])


# ---------------------------------------------------------------------- what each step buys, the shipped default


def test_steps_buy_and_size_buy() -> None:
    points = [
        _pt("tiny_32_s1", 10.0, 0.5, 0.1, params=300, model="tiny_32", psnr=19.0),
        _pt("tiny_32_s4", 15.0, 0.4, 0.2, params=300, model="tiny_32", steps=4, psnr=19.5),
        _pt("tiny_64_s1", 12.0, 0.5, 0.15, params=310, model="tiny_64", psnr=20.0),
        _pt("tiny_64_s4", 30.0, None, None, params=310, model="tiny_64", steps=4, psnr=None),
        _pt("small_128_s1", 60.0, 0.55, 0.08, params=8_700, model="small_128", psnr=21.8),
        _pt(SHIPPED, 160.0, 0.03, 0.95, params=90, family="v2", psnr=20.8),
        {"id": "v2_w8", "model": "v2_w8", "family": "v2", "steps": 1, "skipped": "not trained: x", "params": None},
    ]
    sb = steps_buy(points)
    assert [(b["from"], b["to"], b["steps"]) for b in sb] == [
        ("tiny_32_s1", "tiny_32_s4", [1, 4]),
        ("tiny_64_s1", "tiny_64_s4", [1, 4]),
    ]
    assert sb[0]["d_latency_ms"] == 5.0 and sb[0]["latency_ratio"] == 1.5
    assert sb[0]["d_abs_delta_sr"] == pytest.approx(-0.1) and sb[0]["d_hfr"] == pytest.approx(0.1)
    assert sb[0]["d_psnr_head"] == pytest.approx(0.5) and sb[0]["d_params"] == 0
    assert sb[1]["d_abs_delta_sr"] is None and sb[1]["d_latency_ms"] == 18.0  # not run in closed loop
    zb = {(b["from"], b["to"]): b for b in size_buy(points)}
    # base, v2_w32 and v2_work64 are not in the sweep: their steps are left out; v2_w8 is skipped, and says so.
    assert list(zb) == [
        ("tiny_32_s1", "tiny_64_s1"),
        ("tiny_64_s1", "small_128_s1"),
        ("v2_w8", SHIPPED),
        ("small_128_s1", SHIPPED),
    ]
    assert zb[("tiny_64_s1", "small_128_s1")]["d_params"] == 8_390
    assert zb[("small_128_s1", SHIPPED)]["d_abs_delta_sr"] == pytest.approx(-0.52)
    assert "not trained" in zb[("v2_w8", SHIPPED)]["skipped"] and "d_hfr" not in zb[("v2_w8", SHIPPED)]


def test_shipped_verdict() -> None:
    points = [*_knee_points(), _pt(SHIPPED, 200.0, 0.0, 0.95, params=90_000, family="v2")]
    knee = choose_knee(points, pareto_front(points), pairs=PAIRS)
    assert knee["id"] == "v2"  # as many parameters as the shipped one, faster
    v = shipped_verdict(points, knee)
    assert v["agrees"] is False and "should become v2" in v["verdict"] and v["params"] == 90_000
    points[-1]["chunk_latency_ms"] = 100.0  # now the shipped model is the faster of the two equal-sized ones
    knee = choose_knee(points, pareto_front(points), pairs=PAIRS)
    v = shipped_verdict(points, knee)
    assert knee["id"] == SHIPPED and v["agrees"] is True and "is the knee" in v["verdict"]
    assert shipped_verdict(points[:-1], choose_knee(points[:-1], [], pairs=PAIRS))["verdict"].startswith(
        "v2_shipped is not in this sweep"
    )


# ---------------------------------------------------------------------- models


def test_default_models() -> None:
    """v1 tiny/small trained, base untrained, v2 shipped, and the optional v2 sizes named by their training."""
    models = default_models()
    assert [m.key for m in models] == [
        "tiny_32",
        "tiny_64",
        "small_128",
        "base_128",
        SHIPPED,
        "v2_w8",
        "v2_w32",
        "v2_work64",
    ]
    assert [m.family for m in models] == ["v1"] * 4 + ["v2"] * 4
    assert [m.untrained for m in models] == [False, False, False, True, False, False, False, False]
    assert [m.optional for m in models] == [False] * 5 + [True] * 3
    assert models[0].folder == BENCH_WEIGHTS / "tiny_32" and models[2].folder == Path(V1_CHECKPOINT)
    assert models[4].folder == Path(DEFAULT_CHECKPOINT)
    assert models[5].folder == BENCH_WEIGHTS / "v2_w8" and models[5].trained_by == "scripts/train-bench-variants v2_w8"
    assert dict(models[5].expect) == {"width": 8} and dict(models[7].expect) == {"work_size": 64}
    # "" is the family's packaged model: v1's for v1 (never v2's, which the paired runner would load for "").
    assert TrainedModel("small", 128, "").folder == Path(V1_CHECKPOINT)
    assert TrainedModel("tiny", 32, "x").point_id(4) == "tiny_32_s4" and models[4].point_id(8) == SHIPPED
    with pytest.raises(ValueError, match="family"):
        TrainedModel("tiny", 32, "x", family="v3")
    with pytest.raises(ValueError, match="v2 model needs a name"):
        TrainedModel("v2", 128, "x", family="v2")


def test_train_script_knows_the_v2_sizes() -> None:
    """Every v2 size point's trained_by command names a FLAGS entry of scripts/train-bench-variants."""
    script = (Path(__file__).resolve().parents[3] / "scripts" / "train-bench-variants").read_text()
    for m in default_models()[5:]:
        assert f"[{m.key}]=" in script, m.key


def _rig(width: int = 128, height: int = 128) -> RigConfig:
    rig = RigConfig.load(SIM)
    return rig.model_copy(update={"image_size": ImageSize(width=width, height=height)})


def test_load_a_missing_model_names_it_and_how_to_train_it(tmp_path: Path) -> None:
    with pytest.raises(FileNotFoundError, match=r"no tiny 64x64 model at .*nowhere.*docs/RESULTS\.md"):
        _load(TrainedModel("tiny", 64, str(tmp_path / "nowhere")), _rig())
    (tmp_path / "empty").mkdir()
    v2 = TrainedModel("v2", 128, str(tmp_path / "empty"), family="v2", name="v2_x", trained_by="make-it v2_x")
    with pytest.raises(FileNotFoundError, match=r"no v2 128x128 model .*empty; make-it v2_x"):
        _load(v2, _rig())


def test_load_untrained_is_a_seeded_random_preset_model() -> None:
    """An untrained model is the preset with seed-0 weights (the same twice), the global RNG untouched."""
    torch.manual_seed(123)
    want = torch.rand(3)
    torch.manual_seed(123)
    native = _load(TrainedModel("tiny", 32, "", untrained=True), _rig(32, 32))
    assert torch.equal(torch.rand(3), want)  # fork_rng: the caller's random stream goes on unchanged
    assert isinstance(native, PilWorldModel) and native.config.preset == "tiny"  # at the rig's size: not wrapped
    again = _load(TrainedModel("tiny", 32, "", untrained=True), _rig(32, 32))
    a, b = native.state_dict(), again.state_dict()
    assert a.keys() == b.keys() and all(torch.equal(a[k], b[k]) for k in a)
    resized = _load(TrainedModel("tiny", 32, "", untrained=True), _rig())
    assert isinstance(resized, ResizedWorldModel) and resized.native_size == (32, 32)
    assert parameter_count(resized) == parameter_count(native) == sum(p.numel() for p in native.parameters())


def test_load_v1_small_is_v1_and_resized_on_another_rig() -> None:
    model = _load(TrainedModel("small", 128, str(V1_CHECKPOINT)), _rig())
    assert isinstance(model, PilWorldModel) and (model.info.width, model.info.height) == (128, 128)
    vae, denoiser = (sum(p.numel() for p in m.parameters()) for m in (model.vae, model.denoiser))
    assert parameter_count(model) == vae + denoiser and vae > 0 and denoiser > 0  # v1: VAE + denoiser
    wrapped = _load(TrainedModel("small", 128, str(V1_CHECKPOINT)), _rig(64, 48))
    assert isinstance(wrapped, ResizedWorldModel) and wrapped.native_size == (128, 128)
    with pytest.raises(ValueError, match="not a v1 world model"):
        _load(TrainedModel("small", 128, str(DEFAULT_CHECKPOINT)), _rig())


def test_load_v2_bound_to_the_rig_never_resized(tmp_path: Path) -> None:
    """v2 is loaded as a composite model bound to the rig (its geometry), at the rig's size only; a size point's
    folder must hold the size it is named for."""
    rig = _rig()
    shipped = _load(default_models()[4], rig)
    assert isinstance(shipped, CompositeWorldModel) and shipped._rig is rig
    assert parameter_count(shipped) == sum(p.numel() for p in shipped.net.parameters()) + sum(
        p.numel() for p in shipped.painter.parameters()
    )
    with pytest.raises(ValueError, match="image size"):
        _load(default_models()[4], _rig(64, 64))
    torch.manual_seed(0)
    save_composite(CompositeWorldModel(CompositeConfig(width=8)), tmp_path / "w8")
    w8 = TrainedModel("v2", 128, str(tmp_path / "w8"), family="v2", name="v2_w8", expect=(("width", 8),))
    small = _load(w8, rig)
    assert small.config.width == 8 and parameter_count(small) < parameter_count(shipped)
    wrong = TrainedModel("v2", 128, str(tmp_path / "w8"), family="v2", name="v2_w32", expect=(("width", 32),))
    with pytest.raises(ValueError, match=r"v2_w32 .* has \{'width': 8\}, expected \{'width': 32\}"):
        _load(wrong, rig)
    with pytest.raises(ValueError, match="not a v2"):
        _load(TrainedModel("v2", 128, str(V1_CHECKPOINT), family="v2", name="v2_x"), rig)


# ---------------------------------------------------------------------- closed loop


def _fake_evaluate(calls: list[dict[str, Any]]) -> Any:
    def fake(variants: list[ModelVariant], proto: PairedProtocol, out: Path, **kw: Any) -> dict[str, dict[str, Any]]:
        calls.append({"variants": variants, "proto": proto, "out": out, **kw})
        return {
            v.name: {
                "metrics": {
                    "overall": {
                        "abs_delta_sr": 0.1 * i,
                        "hfr": 0.9,
                        "sr_imag": 0.5,
                        "sr_real": 0.5,
                        "n_subtasks": proto.pairs,
                        "ci95": {"abs_delta_sr": [0.0, 0.2], "hfr": [0.8, 0.95], "sr_real": [0.3, 0.7]},
                    }
                }
            }
            for i, v in enumerate(variants)
        }

    return fake


def test_closed_loop_runs_every_trained_point_as_a_variant(monkeypatch: pytest.MonkeyPatch, tmp_path: Path) -> None:
    """v1 points become resized, adapter-free variants of their model folder at their steps (the packaged v1 by
    its path: "" would be v2), v2 runs at the rig's size without steps; untrained and skipped points are left
    out, and |ΔSR|, HFR, SR and their intervals come back onto the points."""
    calls: list[dict[str, Any]] = []
    monkeypatch.setattr(sa, "evaluate_variants", _fake_evaluate(calls))
    models = {m.key: m for m in default_models()}
    points = [
        _pt("tiny_32_s2", 5.0, None, None, model="tiny_32", steps=2),
        _pt("small_128_s1", 50.0, None, None, model="small_128"),
        _pt("base_128_s1", 500.0, None, None, model="base_128", untrained="random"),
        _pt(SHIPPED, 150.0, None, None, model=SHIPPED, family="v2"),
        _pt("v2_w8", 0.0, None, None, model="v2_w8", family="v2", skipped="not trained"),
    ]
    info = _closed_loop(points, models, tmp_path / "cl", rig=SIM, workers=1, progress=False)

    (call,) = calls
    variants: list[ModelVariant] = call["variants"]
    assert [v.name for v in variants] == ["tiny_32_s2", "small_128_s1", SHIPPED]
    assert [(v.world_model, v.steps, v.resize) for v in variants] == [
        (str(BENCH_WEIGHTS / "tiny_32"), 2, True),
        (str(V1_CHECKPOINT), 1, True),
        (str(DEFAULT_CHECKPOINT), None, False),
    ]
    assert all(v.adapter == "none" and v.history and v.role == "point" for v in variants)
    quick = protocol(True)
    proto: PairedProtocol = call["proto"]
    assert (proto.tasks, proto.checkpoints, proto.subtasks) == (quick.tasks, QUICK_CHECKPOINTS, CLOSED_LOOP_SUBTASKS)
    assert (proto.rounds, proto.seed) == (quick.rounds, quick.seed)
    assert call["out"] == tmp_path / "cl" and call["single_step"] is False and call["workers"] == 1
    assert info["pairs_per_point"] == 3 * 2 * CLOSED_LOOP_SUBTASKS == proto.pairs
    assert info["points"] == ["tiny_32_s2", "small_128_s1", SHIPPED] and info["v1_steps"] == "all"
    assert (points[0]["abs_delta_sr"], points[0]["hfr"], points[0]["sr_imag"]) == (0.0, 0.9, 0.5)
    assert points[0]["ci95"] == {"abs_delta_sr": [0.0, 0.2], "hfr": [0.8, 0.95]} and points[0]["pairs"] == proto.pairs
    assert points[1]["abs_delta_sr"] == pytest.approx(0.1) and points[3]["abs_delta_sr"] == pytest.approx(0.2)
    assert points[2]["abs_delta_sr"] is None and "ci95" not in points[2] and "ci95" not in points[4]


def test_closed_loop_steps_full_mode_runs_v1_at_fewest_and_most_steps() -> None:
    assert closed_loop_steps(STEPS, quick=False) == (1, 16)
    assert closed_loop_steps((4, 2, 8), quick=False) == (2, 8)
    assert closed_loop_steps((4,), quick=False) == (4,)
    assert closed_loop_steps(STEPS, quick=True) == (1,)


def test_closed_loop_quick_runs_v1_at_its_steps_only(monkeypatch: pytest.MonkeyPatch, tmp_path: Path) -> None:
    calls: list[dict[str, Any]] = []
    monkeypatch.setattr(sa, "evaluate_variants", _fake_evaluate(calls))
    models = {m.key: m for m in default_models()}
    points = [
        _pt("tiny_32_s1", 5.0, None, None, model="tiny_32"),
        _pt("tiny_32_s4", 9.0, None, None, model="tiny_32", steps=4),
        _pt(SHIPPED, 150.0, None, None, model=SHIPPED, family="v2"),
    ]
    info = _closed_loop(points, models, tmp_path, rig=SIM, subtasks=1, steps=(1,), workers=None, progress=False)
    assert [v.name for v in calls[0]["variants"]] == ["tiny_32_s1", SHIPPED]
    assert info["pairs_per_point"] == 6 and info["v1_steps"] == [1]
    assert points[1]["abs_delta_sr"] is None and "v1 at 1 step(s) only" in points[1]["closed_loop"]
    with pytest.raises(ValueError, match="no trained point"):
        _closed_loop(points[1:2], models, tmp_path, rig=SIM, steps=(1,), workers=None, progress=False)


# ---------------------------------------------------------------------- a whole sweep on fake models


class _FakeModel(torch.nn.Module):
    def __init__(self, params: int) -> None:
        super().__init__()
        self.w = torch.nn.Parameter(torch.zeros(params))
        self.calls = 0

    def predict(self, *args: Any, **kwargs: Any) -> None:
        self.calls += 1


@pytest.fixture
def fake_sweep(monkeypatch: pytest.MonkeyPatch, tmp_path: Path) -> dict[str, Any]:
    """run_speed_accuracy's stages replaced by fakes recording their arguments: models (params by key), rounds
    (latency by point), single-step scores and the closed loop (v2 accurate, v1 not)."""
    rec: dict[str, Any] = {"single_step": [], "loop": [], "loaded": []}
    params = {"tiny_32": 300_000, "small_128": 8_700_000, "base_128": 61_000_000, SHIPPED: 90_000}
    latency = {"tiny_32": 10.0, "small_128": 60.0, "base_128": 250.0, SHIPPED: 160.0}

    def load(m: TrainedModel, rig: Any) -> _FakeModel:
        rec["loaded"].append(m.key)
        return _FakeModel(params[m.key])

    def env(model: Any, setup: Any, *, steps: int | None = None) -> Any:
        return SimpleNamespace(model=model, steps=steps)

    def rounds(envs: dict[str, Any], setup: Any, *, repeats: int, warmup: int) -> dict[str, list[float]]:
        rec["rounds"] = (list(envs), repeats, warmup)
        out = {}
        for pid, e in envs.items():
            for _ in range(warmup + repeats):
                e.model.predict()
            out[pid] = [latency[pid.rsplit("_s", 1)[0] if pid != SHIPPED else pid] * (e.steps or 1)] * repeats
        return out

    def bench(model: Any, **kw: Any) -> dict[str, Any]:
        rec["single_step"].append(kw)
        view = {"psnr_pooled": 20.0 + kw["clips"] / 100, "ssim": 0.8}
        return {
            "per_view": {"cam_high": view},
            "psnr_pooled": 19.0,
            "gain_over_frozen_pooled_db": {"cam_high": 1.0},
            "clips": kw["clips"],
        }

    def evaluate(variants: list[ModelVariant], proto: PairedProtocol, out: Path, **kw: Any) -> Any:
        rec["loop"].append((variants, proto, out))
        return {
            v.name: {
                "metrics": {
                    "overall": {
                        "abs_delta_sr": 0.02 if v.name == SHIPPED else 0.5,
                        "hfr": 0.95 if v.name == SHIPPED else 0.05,
                        "sr_imag": 0.5,
                        "sr_real": 0.5,
                        "n_subtasks": proto.pairs,
                    }
                }
            }
            for v in variants
        }

    monkeypatch.setattr(sa, "_load", load)
    monkeypatch.setattr(sa, "evaluate_variants", evaluate)
    monkeypatch.setattr(cl, "round_setup", lambda rig, task: SimpleNamespace(spec=SimpleNamespace(frames=15, stride=3)))
    monkeypatch.setattr(cl, "imagined_env", env)
    monkeypatch.setattr(cl, "time_rounds", rounds)
    monkeypatch.setattr(wm, "heldout_dataset", lambda rig_path, **kw: tmp_path / "heldout")
    monkeypatch.setattr(wm, "run_world_model_bench", bench)
    rec["tmp"] = tmp_path
    return rec


def _fake_models(tmp_path: Path) -> list[TrainedModel]:
    keep = ("tiny_32", "small_128", "base_128", SHIPPED)
    missing = TrainedModel(
        "v2", 128, str(tmp_path / "nowhere"), family="v2", name="v2_w8", optional=True, trained_by="train it v2_w8"
    )
    return [m for m in default_models() if m.key in keep] + [missing]


@pytest.mark.parametrize("quick", [False, True])
def test_sweep_wiring_on_fake_models(fake_sweep: dict[str, Any], quick: bool) -> None:
    """Every point timed as whole rounds (v2 without steps), scored single-step (untrained: not), run in closed
    loop (quick: v1 at 1 step); the missing v2 size is a skipped entry out of front and knee; the knee is the
    accurate v2, which is also the shipped default; plain JSON, and the tables print it."""
    tmp = fake_sweep["tmp"]
    r = run_speed_accuracy(
        rig=SIM, quick=quick, models=_fake_models(tmp), steps=[1, 4], clips=3, out=tmp / "out", progress=False
    )
    ids = [p["id"] for p in r["points"]]
    v1 = ["tiny_32_s1", "tiny_32_s4", "small_128_s1", "small_128_s4", "base_128_s1", "base_128_s4"]
    assert ids == [*v1, SHIPPED, "v2_w8"]
    skipped = r["points"][-1]
    assert skipped["skipped"] == "not trained: train it v2_w8" and "chunk_latency_ms" not in skipped
    assert fake_sweep["loaded"] == ["tiny_32", "small_128", "base_128", SHIPPED]  # once each, never the missing
    timed, repeats, warmup = fake_sweep["rounds"]
    assert timed == [*v1, SHIPPED] and (repeats, warmup) == ((3, 1) if quick else (10, 2))
    by = {p["id"]: p for p in r["points"]}
    assert by["small_128_s4"]["chunk_latency_ms"] == 240.0 and by[SHIPPED]["chunk_latency_ms"] == 160.0
    assert by["tiny_32_s1"]["realtime_factor"] == 150.0  # 1.5 s of robot time in 10 ms
    assert all(by[i]["predict_latency_ms"] >= 0 for i in timed)
    assert by[SHIPPED]["params"] == 90_000 and by["base_128_s1"]["params"] == 61_000_000
    assert "no sampling steps" in by[SHIPPED]["note"] and by[SHIPPED]["steps"] == 1
    scored = [kw["steps"] for kw in fake_sweep["single_step"]]
    assert scored == [1, 4, 1, 4, None]  # v1 trained points, then v2 (its steps ignored); base is not scored
    assert all(kw["clips"] == 3 and kw["repeats"] == 1 for kw in fake_sweep["single_step"])
    assert by["base_128_s1"]["psnr_head"] is None and by["base_128_s1"]["abs_delta_sr"] is None

    ((variants, proto, out),) = fake_sweep["loop"]
    assert out == tmp / "out"
    if quick:
        assert [v.name for v in variants] == ["tiny_32_s1", "small_128_s1", SHIPPED] and proto.pairs == 6
        assert "v1 at 1 step(s) only" in by["tiny_32_s4"]["closed_loop"] and by["tiny_32_s4"]["abs_delta_sr"] is None
    else:
        assert [v.name for v in variants] == ["tiny_32_s1", "tiny_32_s4", "small_128_s1", "small_128_s4", SHIPPED]
        assert proto.pairs == 18
    assert r["closed_loop"]["pairs_per_point"] == proto.pairs
    assert set(r["stages_s"]) == {"latency", "single_step", "closed_loop"} and min(r["stages_s"].values()) >= 0

    assert SHIPPED in r["front_ids"] and "tiny_32_s1" in r["front_ids"] and "v2_w8" not in r["front_ids"]
    assert all(not i.startswith("base") for i in r["front_ids"])
    d = r["default"]
    assert d["id"] == SHIPPED and d["pairs"] == proto.pairs and d["reaching"] == [SHIPPED]
    assert r["shipped_default"]["agrees"] is True
    assert r["single_step_knee"]["id"] is not None
    assert {b["to"] for b in r["steps_buy"]} == {"tiny_32_s4", "small_128_s4", "base_128_s4"}
    assert [(b["from"], b["to"]) for b in r["size_buy"]] == [
        ("small_128_s1", "base_128_s1"),
        ("v2_w8", SHIPPED),
        ("small_128_s1", SHIPPED),
    ]
    assert "whole imagined round" in r["latency"]["measures"]
    assert json.loads(json.dumps(r)) == r
    text = speed_accuracy_tables(r)
    assert f"Knee: **{SHIPPED}**" in text and "not trained: train it v2_w8" in text and "is the knee" in text
    assert "| 1 → 4 sampling steps | tiny_32_s1 → tiny_32_s4 | +0 | +30.0 (×4.00) |" in text
    assert "| v1: small -> base preset (base untrained: latency only) | small_128_s1 → base_128_s1 | +52.30 M |" in text
    assert "| v2_shipped | v2 | 128x128 | — (1 pass) | 0.09 M | 160.0 | 9.4 |" in text


def test_sweep_without_closed_loop_has_no_knee(fake_sweep: dict[str, Any]) -> None:
    tmp = fake_sweep["tmp"]
    r = run_speed_accuracy(
        rig=SIM, models=_fake_models(tmp), steps=[1], clips=1, out=tmp / "out", closed_loop=False, progress=False
    )
    assert fake_sweep["loop"] == [] and r["front_ids"] == [] and r["default"]["id"] is None
    assert "closed loop not run" in r["default"]["none"] and r["shipped_default"]["agrees"] is None
    assert "Knee: none" in speed_accuracy_tables(r)


@pytest.mark.parametrize(("quick", "repeats", "want"), [(True, None, 3), (False, None, 10), (True, 5, 5)])
def test_timed_rounds_per_point(fake_sweep: dict[str, Any], quick: bool, repeats: int | None, want: int) -> None:
    tmp = fake_sweep["tmp"]
    r = run_speed_accuracy(
        rig=SIM,
        quick=quick,
        models=_fake_models(tmp)[:1],
        steps=[1],
        clips=1,
        repeats=repeats,
        out=tmp / "out",
        closed_loop=False,
        progress=False,
    )
    assert fake_sweep["rounds"][1] == want and r["latency_repeats"] == want == r["latency"]["repeats"]


def test_zero_repeats_and_a_missing_model_fail_before_any_work(monkeypatch: pytest.MonkeyPatch, tmp_path: Path) -> None:
    collected: list[dict[str, Any]] = []

    def record(rig_path: str | Path, **kw: Any) -> Path:
        collected.append(kw)
        return tmp_path / "heldout"

    monkeypatch.setattr(wm, "heldout_dataset", record)
    monkeypatch.setattr(cl, "round_setup", lambda *a: pytest.fail("timed despite a bad argument"))
    kw: dict[str, Any] = {"rig": SIM, "steps": [1], "clips": 1, "out": tmp_path / "out", "progress": False}
    with pytest.raises(FileNotFoundError, match="tiny 64x64"):
        run_speed_accuracy(models=[TrainedModel("tiny", 64, str(tmp_path / "nowhere"))], repeats=1, **kw)
    with pytest.raises(ValueError, match="repeats"):
        run_speed_accuracy(models=default_models()[:1], repeats=0, **kw)
    assert collected == []


# ---------------------------------------------------------------------- one small real sweep


@pytest.fixture(scope="module")
def sweep(tmp_path_factory: pytest.TempPathFactory) -> Iterator[tuple[dict[str, Any], list[dict[str, Any]], Path]]:
    """v1 tiny 32×32 (trained) at 1 and 2 steps, the shipped v2, an untrained tiny, and a v2 size without
    weights; 2 clips, 1 timed round, closed loop off. The held-out set is collected (once, in a temporary
    cache) for one task instead of all three; the arguments run_speed_accuracy asked for are recorded."""
    tmp = tmp_path_factory.mktemp("speed_accuracy")
    asked: list[dict[str, Any]] = []
    real_heldout = wm.heldout_dataset

    def one_task_heldout(rig_path: str | Path, **kw: Any) -> Path:
        asked.append({"rig": rig_path, **kw})
        return real_heldout(rig_path, **{**kw, "tasks": [HELDOUT_TASK], "episodes": 1, "workers": 1})

    models = [m for m in default_models() if m.key in ("tiny_32", SHIPPED)]
    models += [
        TrainedModel("tiny", 64, "", untrained=True),
        TrainedModel("v2", 128, str(tmp / "none"), family="v2", name="v2_w8", optional=True, trained_by="t v2_w8"),
    ]
    with pytest.MonkeyPatch.context() as mp:
        mp.setenv("PILWORLD_CACHE", str(tmp / "cache"))  # held-out runs and decoded clips
        mp.setattr(wm, "heldout_dataset", one_task_heldout)
        r = run_speed_accuracy(
            rig=SIM,
            models=models,
            steps=[1, 2],
            clips=2,
            repeats=1,
            out=tmp / "out",
            closed_loop=False,
            progress=False,
        )
    yield r, asked, tmp


@pytest.mark.slow
def test_sweep_points(sweep: tuple[dict[str, Any], list[dict[str, Any]], Path]) -> None:
    """One point per v1 model × steps and one per v2 model; trained points scored on the clips and timed as whole
    rounds, the untrained one only timed, the missing v2 size skipped."""
    r, asked, tmp = sweep
    assert r["bench"] == "speed-accuracy" and r["quick"] is False and r["heldout_clips"] == 2
    assert len(asked) == 1 and asked[0]["tasks"] == list(TASK_NAMES) and asked[0]["seed0"] == wm.HELDOUT_SEED0
    points = r["points"]
    assert [p["id"] for p in points] == ["tiny_32_s1", "tiny_32_s2", SHIPPED, "tiny_64_s1", "tiny_64_s2", "v2_w8"]
    for p in points[:5]:
        assert p["chunk_latency_ms"] > 0 and p["realtime_factor"] > 0, p["id"]
        assert 0 < p["predict_latency_ms"] <= p["chunk_latency_ms"], p["id"]
        assert p["abs_delta_sr"] is None and p["hfr"] is None, p["id"]  # closed loop not run
        assert isinstance(p["params"], int) and p["params"] > 0
    for p in points[:3]:
        assert p["clips"] == 2 and "untrained" not in p
        for key in ("psnr_head", "psnr_pooled", "gain_over_frozen_head_db"):
            assert isinstance(p[key], float) and math.isfinite(p[key]), (p["id"], key)
        assert 10.0 < p["psnr_head"] < 100.0 and 0.0 < p["ssim_head"] <= 1.0
    assert points[2]["family"] == "v2" and "memory empty" in points[2]["single_step_note"]
    assert points[2]["params"] < points[0]["params"]  # 0.09 M against v1 tiny's 0.31 M
    for p in points[3:5]:
        assert p["clips"] == 0 and p["psnr_head"] is None and "not trained" in p["untrained"]
    assert points[5]["skipped"] == "not trained: t v2_w8"
    assert r["closed_loop"] == {"skipped": "closed_loop=False"} and r["default"]["id"] is None
    assert r["single_step_knee"]["id"] in {"tiny_32_s1", "tiny_32_s2", SHIPPED}
    assert not (tmp / "out").exists()  # no closed-loop run folder
    assert json.loads(json.dumps(r)) == r  # plain JSON


@pytest.mark.slow
def test_sweep_chart(sweep: tuple[dict[str, Any], list[dict[str, Any]], Path], tmp_path: Path) -> None:
    """The chart draws the sweep's points (untrained and skipped ones left out), and with closed-loop figures,
    the front, the knee and the shipped default too."""
    r, _, _ = sweep
    path = speed_accuracy_chart(r["points"], r["front_ids"], tmp_path / "sub" / "sa.png")
    assert path == tmp_path / "sub" / "sa.png" and path.read_bytes()[:8] == PNG
    loop = [
        p if p.get("skipped") or p.get("untrained") else p | {"abs_delta_sr": 0.05 * p["steps"], "hfr": 0.9}
        for p in r["points"]
    ]
    front = pareto_front(loop)
    knee = choose_knee(loop, front, pairs=PAIRS)["id"]
    out = speed_accuracy_chart(loop, front, tmp_path / "loop.png", knee=knee, shipped=SHIPPED)
    assert out.read_bytes()[:8] == PNG


def test_chart_of_hand_made_points(tmp_path: Path) -> None:
    """Fast: both families, a front, the knee and the shipped default marked, and a panel with nothing to draw."""
    points = [*_knee_points(), _pt(SHIPPED, 200.0, 0.0, 0.95, params=90_000, family="v2")]
    front = pareto_front(points)
    path = speed_accuracy_chart(points, front, tmp_path / "c.png", knee="v2", shipped=SHIPPED)
    assert path.read_bytes()[:8] == PNG
    bare = [_pt("x", 10.0, None, None, psnr=None)]
    assert speed_accuracy_chart(bare, [], tmp_path / "bare.png").read_bytes()[:8] == PNG


# ---------------------------------------------------------------------- CLI


def test_cli_rejects_bad_arguments(
    monkeypatch: pytest.MonkeyPatch, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """--steps, --clips, --repeats and --subtasks below 1 exit with 2 naming the option, before any work."""

    def never(**kw: Any) -> dict[str, Any]:
        raise AssertionError("the bench ran despite a bad argument")

    monkeypatch.setattr(sa, "run_speed_accuracy", never)
    out = tmp_path / "out"
    for bad in (["--steps", "0"], ["--steps", "1,2,-4"]):
        assert main(["bench", "speed-accuracy", *bad, "--out", str(out)]) == 2, bad
        err = capsys.readouterr().err
        assert "--steps" in err and "expected integers >= 1" in err, bad
    for bad in (["--clips", "0"], ["--repeats", "0"], ["--subtasks", "-3"]):
        assert main(["bench", "speed-accuracy", *bad, "--out", str(out)]) == 2, bad
        err = capsys.readouterr().err
        assert bad[0] in err and "expected at least 1" in err, bad
    assert not out.exists()


def test_cli_prints_the_knee_and_the_shipped_default(
    fake_sweep: dict[str, Any], monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    """On fake models: the summary names the knee, the shipped default's verdict and every point; the quick run's
    folder is the quick default unless --out; --json's last line is the result."""
    tmp = fake_sweep["tmp"]
    real = sa.run_speed_accuracy
    seen: list[dict[str, Any]] = []

    def run(**kw: Any) -> dict[str, Any]:
        seen.append(kw)
        return real(**{**kw, "models": _fake_models(tmp), "steps": [1], "clips": 1, "out": tmp / "o"})

    monkeypatch.setattr(sa, "run_speed_accuracy", run)
    chart = tmp / "c.png"
    assert main(["bench", "speed-accuracy", "--quick", "--chart", str(chart), "--json"]) == 0
    lines = capsys.readouterr().out.strip().splitlines()
    assert seen[0]["out"] == Path("bench_runs") / "speed-accuracy-quick" and seen[0]["quick"] is True
    text = "\n".join(lines[:-1])
    assert f"knee: {SHIPPED} (v2 128x128, 90,000 parameters)" in text and "is the knee" in text
    assert "tiny_32_s1" in text and "not trained: train it v2_w8" in text and "whole imagined round" in text
    r = json.loads(lines[-1])
    assert r["default"]["id"] == SHIPPED and r["chart"] == str(chart) and chart.read_bytes()[:8] == PNG
