"""``pilworld bench speed-accuracy``: the Pareto front, the knee rule, model loading, the closed-loop
variants, one small end-to-end sweep (the packaged model and an untrained tiny one, 1 and 2 steps, on a
one-task held-out set in a temporary cache) with its chart, and the CLI's argument errors.
"""

from __future__ import annotations

import json
import math
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest
import torch

import pilworld.bench.speed_accuracy as sa
import pilworld.bench.world_model as wm
from hw_drivers.sim.tasks import TASK_NAMES
from pilworld.bench.charts import speed_accuracy_chart
from pilworld.bench.paired import QUICK_CHECKPOINTS, protocol
from pilworld.bench.speed_accuracy import (
    CLOSED_LOOP_SUBTASKS,
    KNEE_DB,
    TrainedModel,
    _closed_loop,
    _load,
    choose_default,
    default_models,
    pareto_front,
    run_speed_accuracy,
)
from pilworld.bench.variants import BENCH_WEIGHTS, ModelVariant, PairedProtocol
from pilworld.cli.main import main
from pilworld.world_model.model import PilWorldModel
from pilworld.world_model.resized import ResizedWorldModel

SIM = "configs/rig/sim_dual_ur5e.yaml"
PNG = b"\x89PNG\r\n\x1a\n"
HELDOUT_TASK = "stack_blocks"  # 2 subtasks: the cheapest task to collect whole


def _pt(
    pid: str,
    latency: float,
    psnr: float | None,
    *,
    rt: float = 2.0,
    preset: str = "small",
    size: str = "128x128",
    steps: int = 1,
) -> dict[str, Any]:
    return {
        "id": pid,
        "preset": preset,
        "size": size,
        "steps": steps,
        "chunk_latency_ms": latency,
        "realtime_factor": rt,
        "psnr_head": psnr,
    }


# ---------------------------------------------------------------------- the front


def test_pareto_front_keeps_non_dominated_points_sorted_by_latency() -> None:
    """Dominated points (slower and no better, or as fast and worse) and unscored points are left out."""
    points = [
        _pt("d", 40.0, 26.0),
        _pt("c", 30.0, 24.0),  # slower than b and worse
        _pt("a", 10.0, 20.0),
        _pt("e", 5.0, None),  # fastest, but no accuracy: not on the front, and dominates nothing
        _pt("b", 20.0, 25.0),
        _pt("g", 10.0, 19.0),  # as fast as a, worse
        _pt("h", 50.0, 26.0),  # as good as d, slower
    ]
    assert pareto_front(points) == ["a", "b", "d"]
    assert pareto_front([p for p in points if p["id"] != "b"]) == ["a", "c", "d"]  # c is no longer beaten


def test_pareto_front_ties_and_empty() -> None:
    """Two identical points both stay (neither is strictly better); no scored point gives an empty front."""
    assert set(pareto_front([_pt("x", 10.0, 20.0), _pt("y", 10.0, 20.0)])) == {"x", "y"}
    assert pareto_front([_pt("x", 10.0, None), _pt("y", 20.0, None)]) == []
    assert pareto_front([]) == []
    assert pareto_front([_pt("only", 99.0, 1.0)]) == ["only"]


# ---------------------------------------------------------------------- the knee


def test_choose_default_picks_the_fastest_real_time_point_within_the_knee() -> None:
    """A (fast, too inaccurate) is skipped, B (within KNEE_DB of the best) is chosen over the best C."""
    best = 25.0
    points = [
        _pt("A", 10.0, best - 2 * KNEE_DB, rt=4.0, steps=1),
        _pt("B", 20.0, best - 0.5 * KNEE_DB, rt=2.0, steps=2),
        _pt("C", 40.0, best, rt=1.0, steps=8),
    ]
    front = pareto_front(points)
    assert front == ["A", "B", "C"]
    d = choose_default(points, front)
    assert d == {
        "id": "B",
        "preset": "small",
        "size": "128x128",
        "steps": 2,
        "chunk_latency_ms": 20.0,
        "psnr_head": best - 0.5 * KNEE_DB,
        "best_psnr_head": best,
        "rule": f"fastest real-time point of the front within {KNEE_DB} dB of the best head-view PSNR",
    }
    # B not real time: C is (a realtime factor of exactly 1 keeps pace).
    points[1]["realtime_factor"] = 0.5
    assert choose_default(points, front)["id"] == "C"
    # Exactly KNEE_DB below the best still reaches the accuracy.
    points[1] |= {"realtime_factor": 2.0, "psnr_head": best - KNEE_DB}
    assert choose_default(points, front)["id"] == "B"
    # Only front points count: without B on the front, C (not the faster, inaccurate A).
    assert choose_default(points, ["A", "C"])["id"] == "C"


def test_choose_default_falls_back_to_the_fastest_front_point() -> None:
    """No front point keeps real time: the fastest front point, whatever its accuracy."""
    points = [
        _pt("slow_good", 400.0, 30.0, rt=0.1),
        _pt("fast_bad", 100.0, 20.0, rt=0.5),
        _pt("mid", 200.0, 25.0, rt=0.2),
    ]
    d = choose_default(points, pareto_front(points))
    assert d["id"] == "fast_bad" and d["best_psnr_head"] == 30.0


def test_choose_default_without_a_front_raises() -> None:
    points = [_pt("untrained", 10.0, None)]
    with pytest.raises(ValueError, match="no point has an accuracy"):
        choose_default(points, pareto_front(points))
    with pytest.raises(ValueError, match="no point has an accuracy"):
        choose_default([_pt("a", 1.0, 20.0)], [])


# ---------------------------------------------------------------------- models


def test_trained_model_keys_and_default_models() -> None:
    assert TrainedModel("tiny", 32, "x").key == "tiny_32"
    models = default_models()
    assert [m.key for m in models] == ["tiny_32", "tiny_64", "small_128", "base_128"]
    assert [m.untrained for m in models] == [False, False, False, True]
    assert models[0].path == str(BENCH_WEIGHTS / "tiny_32") and models[2].path == ""  # "" = packaged


def test_load_a_missing_model_names_preset_and_docs(tmp_path: Path) -> None:
    """A folder that does not exist, or has no config.json, is a FileNotFoundError saying how to train it."""
    with pytest.raises(FileNotFoundError, match=r"no tiny 64x64 model at .*nowhere.*docs/RESULTS\.md"):
        _load(TrainedModel("tiny", 64, str(tmp_path / "nowhere")), (128, 128))
    (tmp_path / "empty").mkdir()
    with pytest.raises(FileNotFoundError, match=r"tiny 32x32.*docs/RESULTS\.md"):
        _load(TrainedModel("tiny", 32, str(tmp_path / "empty")), (128, 128))


def test_load_untrained_is_a_seeded_random_preset_model() -> None:
    """An untrained model is the preset with seed-0 weights (the same twice), the global RNG untouched."""
    torch.manual_seed(123)
    want = torch.rand(3)
    torch.manual_seed(123)
    native = _load(TrainedModel("tiny", 32, "", untrained=True), (32, 32))
    assert torch.equal(torch.rand(3), want)  # fork_rng: the caller's random stream goes on unchanged
    assert isinstance(native, PilWorldModel)  # already at the rig's size: not wrapped
    assert native.config.preset == "tiny"
    again = _load(TrainedModel("tiny", 32, "", untrained=True), (32, 32))
    a, b = native.state_dict(), again.state_dict()
    assert a.keys() == b.keys() and all(torch.equal(a[k], b[k]) for k in a)
    resized = _load(TrainedModel("tiny", 32, "", untrained=True), (128, 128))
    assert isinstance(resized, ResizedWorldModel)
    assert (resized.info.width, resized.info.height) == (128, 128) and resized.native_size == (32, 32)


def test_load_the_packaged_model_resized_to_the_rig() -> None:
    """The packaged small model (128×128) is used as is on a 128×128 rig and wrapped on another size."""
    model = _load(TrainedModel("small", 128, ""), (128, 128))
    assert isinstance(model, PilWorldModel) and (model.info.width, model.info.height) == (128, 128)
    wrapped = _load(TrainedModel("small", 128, ""), (64, 48))
    assert isinstance(wrapped, ResizedWorldModel)
    assert (wrapped.info.width, wrapped.info.height) == (64, 48) and wrapped.native_size == (128, 128)


# ---------------------------------------------------------------------- closed loop


def test_closed_loop_runs_every_trained_point_as_a_variant(monkeypatch: pytest.MonkeyPatch, tmp_path: Path) -> None:
    """Each trained point becomes a resized, adapter-free variant at its steps; the untrained one is left
    out; |ΔSR|, HFR and imagined SR come back onto the points."""
    calls: list[dict[str, Any]] = []

    def fake_evaluate(
        variants: list[ModelVariant], proto: PairedProtocol, out: Path, **kw: Any
    ) -> dict[str, dict[str, Any]]:
        calls.append({"variants": variants, "proto": proto, "out": out, **kw})
        return {
            v.name: {"metrics": {"overall": {"abs_delta_sr": 0.1 * i, "hfr": 0.9, "sr_imag": 0.5}}}
            for i, v in enumerate(variants)
        }

    monkeypatch.setattr(sa, "evaluate_variants", fake_evaluate)
    models = [
        TrainedModel("tiny", 32, "/m/tiny_32"),
        TrainedModel("small", 128, ""),
        TrainedModel("base", 128, "", True),
    ]
    points = [
        _pt("tiny_32_s2", 5.0, 20.0, preset="tiny", size="32x32", steps=2) | {"abs_delta_sr": None, "hfr": None},
        _pt("small_128_s1", 50.0, 25.0) | {"abs_delta_sr": None, "hfr": None},
        _pt("base_128_s1", 500.0, None, preset="base") | {"abs_delta_sr": None, "hfr": None},
    ]
    info = _closed_loop(points, models, tmp_path / "cl", rig=SIM, workers=1, progress=False)

    (call,) = calls
    variants: list[ModelVariant] = call["variants"]
    assert [v.name for v in variants] == ["tiny_32_s2", "small_128_s1"]
    assert [(v.world_model, v.steps) for v in variants] == [("/m/tiny_32", 2), ("", 1)]
    assert all(v.adapter == "none" and v.resize and v.history and v.role == "point" for v in variants)
    quick = protocol(True)
    proto: PairedProtocol = call["proto"]
    assert (proto.tasks, proto.checkpoints, proto.subtasks) == (quick.tasks, QUICK_CHECKPOINTS, CLOSED_LOOP_SUBTASKS)
    assert (proto.rounds, proto.seed) == (quick.rounds, quick.seed)
    assert call["out"] == tmp_path / "cl" and call["single_step"] is False and call["workers"] == 1
    assert info == {
        "pairs_per_point": 3 * 2 * CLOSED_LOOP_SUBTASKS,
        "checkpoints": list(QUICK_CHECKPOINTS),
        "out": str(tmp_path / "cl"),
    }
    assert (points[0]["abs_delta_sr"], points[0]["hfr"], points[0]["sr_imag"]) == (0.0, 0.9, 0.5)
    assert points[1]["abs_delta_sr"] == pytest.approx(0.1)
    assert points[2]["abs_delta_sr"] is None and "sr_imag" not in points[2]


# ---------------------------------------------------------------------- end to end


@pytest.fixture(scope="module")
def sweep(tmp_path_factory: pytest.TempPathFactory) -> Iterator[tuple[dict[str, Any], list[dict[str, Any]], Path]]:
    """The packaged small model and an untrained tiny one at 1 and 2 steps, 2 clips, closed loop off.

    The held-out set is collected (once, in a temporary cache) for one task instead of all three; the
    arguments run_speed_accuracy asked for are recorded.
    """
    tmp = tmp_path_factory.mktemp("speed_accuracy")
    asked: list[dict[str, Any]] = []
    real_heldout = wm.heldout_dataset

    def one_task_heldout(rig_path: str | Path, **kw: Any) -> Path:
        asked.append({"rig": rig_path, **kw})
        return real_heldout(rig_path, **{**kw, "tasks": [HELDOUT_TASK], "episodes": 1, "workers": 1})

    with pytest.MonkeyPatch.context() as mp:
        mp.setenv("PILWORLD_CACHE", str(tmp / "cache"))  # held-out runs and decoded clips
        mp.setattr(wm, "heldout_dataset", one_task_heldout)
        r = run_speed_accuracy(
            rig=SIM,
            models=[TrainedModel("small", 128, ""), TrainedModel("tiny", 32, "", untrained=True)],
            steps=[1, 2],
            clips=2,
            repeats=1,
            out=tmp / "out",
            closed_loop=False,
            progress=False,
        )
    yield r, asked, tmp


def test_sweep_points(sweep: tuple[dict[str, Any], list[dict[str, Any]], Path]) -> None:
    """One point per model × steps; trained points scored on the clips, the untrained one only timed."""
    r, asked, tmp = sweep
    assert r["bench"] == "speed-accuracy" and r["quick"] is False and r["heldout_clips"] == 2
    assert len(asked) == 1 and asked[0]["tasks"] == list(TASK_NAMES) and asked[0]["seed0"] == wm.HELDOUT_SEED0
    points = r["points"]
    assert [p["id"] for p in points] == ["small_128_s1", "small_128_s2", "tiny_32_s1", "tiny_32_s2"]
    assert [(p["preset"], p["size"], p["steps"]) for p in points] == [
        ("small", "128x128", 1),
        ("small", "128x128", 2),
        ("tiny", "32x32", 1),
        ("tiny", "32x32", 2),
    ]
    for p in points:
        assert p["chunk_latency_ms"] > 0 and p["realtime_factor"] > 0, p["id"]
        assert p["abs_delta_sr"] is None and p["hfr"] is None, p["id"]  # closed loop not run
    for p in points[:2]:
        assert p["clips"] == 2 and "untrained" not in p
        for key in ("psnr_head", "psnr_pooled", "gain_over_frozen_head_db"):
            assert isinstance(p[key], float) and math.isfinite(p[key]), (p["id"], key)
        assert 10.0 < p["psnr_head"] < 100.0 and 0.0 < p["ssim_head"] <= 1.0
    for p in points[2:]:
        assert p["clips"] == 1
        assert p["psnr_head"] is None and p["ssim_head"] is None and p["psnr_pooled"] is None
        assert p["gain_over_frozen_head_db"] is None
        assert isinstance(p["untrained"], str) and "not trained" in p["untrained"]
    assert "skipped" in r["closed_loop"]
    assert not (tmp / "out").exists()  # no closed-loop run folder
    assert json.loads(json.dumps(r)) == r  # plain JSON


def test_sweep_front_and_default(sweep: tuple[dict[str, Any], list[dict[str, Any]], Path]) -> None:
    """The front holds trained points only, the default is the knee of that front, compared with small/1 step."""
    r, _, _ = sweep
    points = r["points"]
    front = r["front_ids"]
    assert front and set(front) <= {"small_128_s1", "small_128_s2"}  # the untrained tiny points never
    assert front == pareto_front(points)
    assert r["front"] == [p for p in points if p["id"] in front]
    d = r["default"]
    assert d == choose_default(points, front) and d["id"] in front
    chosen = next(p for p in points if p["id"] == d["id"])
    assert (d["preset"], d["steps"], d["chunk_latency_ms"]) == (
        chosen["preset"],
        chosen["steps"],
        chosen["chunk_latency_ms"],
    )
    assert d["best_psnr_head"] == max(p["psnr_head"] for p in points if p["id"] in front)
    shipped = r["shipped_default"]
    assert isinstance(shipped["agrees"], bool) and shipped["agrees"] == (d["id"] == "small_128_s1")
    assert (shipped["preset"], shipped["steps"]) == ("small", 1)
    assert (
        shipped["chunk_latency_ms"] == points[0]["chunk_latency_ms"] and shipped["psnr_head"] == points[0]["psnr_head"]
    )


# The |ΔSR| panel has no labelled artist without closed-loop figures (charts.py calls legend() anyway).
@pytest.mark.filterwarnings("ignore:No artists with labels found to put in legend")
def test_sweep_chart(sweep: tuple[dict[str, Any], list[dict[str, Any]], Path], tmp_path: Path) -> None:
    """The chart draws the sweep's points (unscored ones skipped), and with closed-loop figures too."""
    r, _, _ = sweep
    path = speed_accuracy_chart(r["points"], r["front_ids"], tmp_path / "sub" / "sa.png")
    assert path == tmp_path / "sub" / "sa.png" and path.read_bytes()[:8] == PNG
    with_loop = [p | {"abs_delta_sr": None if p["psnr_head"] is None else 0.05 * p["steps"]} for p in r["points"]]
    assert speed_accuracy_chart(with_loop, r["front_ids"], tmp_path / "loop.png").read_bytes()[:8] == PNG


def test_a_missing_model_fails_before_the_heldout_set_is_collected(
    monkeypatch: pytest.MonkeyPatch, tmp_path: Path
) -> None:
    collected: list[dict[str, Any]] = []

    def record(rig_path: str | Path, **kw: Any) -> Path:
        collected.append(kw)
        return tmp_path / "heldout"

    monkeypatch.setattr(wm, "heldout_dataset", record)
    with pytest.raises(FileNotFoundError, match="tiny 64x64"):
        run_speed_accuracy(
            rig=SIM,
            models=[TrainedModel("tiny", 64, str(tmp_path / "nowhere"))],
            steps=[1],
            clips=1,
            repeats=1,
            out=tmp_path / "out",
            closed_loop=False,
            progress=False,
        )
    assert collected == []


# ---------------------------------------------------------------------- CLI


def test_cli_rejects_bad_steps_and_clips(
    monkeypatch: pytest.MonkeyPatch, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """--steps below 1 and --clips below 1 exit with 2 naming the option, before any work."""

    def never(**kw: Any) -> dict[str, Any]:
        raise AssertionError("the bench ran despite a bad argument")

    monkeypatch.setattr(sa, "run_speed_accuracy", never)
    out = tmp_path / "out"
    for bad in (["--steps", "0"], ["--steps", "1,2,-4"]):
        assert main(["bench", "speed-accuracy", *bad, "--out", str(out)]) == 2, bad
        err = capsys.readouterr().err
        assert "--steps" in err and "expected integers >= 1" in err, bad
    for bad in (["--clips", "0"], ["--clips", "-3"]):
        assert main(["bench", "speed-accuracy", *bad, "--out", str(out)]) == 2, bad
        err = capsys.readouterr().err
        assert "--clips" in err and "expected at least 1" in err, bad
    assert not out.exists()


@pytest.mark.parametrize(
    ("quick", "repeats", "want"), [(True, None, 3), (False, None, 10), (True, 5, 5), (False, 0, 0)]
)
def test_timed_calls_per_point(
    monkeypatch: pytest.MonkeyPatch, tmp_path: Path, quick: bool, repeats: int | None, want: int
) -> None:
    """Quick mode times 3 calls per point (the untrained base at 16 steps costs ~8 s a call), full mode 10;
    an explicit --repeats wins either way (0 too: the bench itself refuses it); the JSON says how many."""
    timed: list[int] = []

    def bench(model: Any, **kw: Any) -> dict[str, Any]:
        timed.append(kw["repeats"])
        view = {"psnr_pooled": 20.0, "ssim": 0.5}
        return {
            "per_view": {"cam_high": view},
            "chunk_latency_ms": 100.0,
            "realtime_factor": 2.0,
            "psnr_pooled": 20.0,
            "gain_over_frozen_pooled_db": {"cam_high": 1.0},
            "clips": kw["clips"],
        }

    monkeypatch.setattr(wm, "heldout_dataset", lambda rig_path, **kw: tmp_path / "heldout")
    monkeypatch.setattr(wm, "run_world_model_bench", bench)
    monkeypatch.setattr(sa, "_load", lambda m, size: object())  # the model itself is never called here
    r = run_speed_accuracy(
        rig=SIM,
        quick=quick,
        models=[TrainedModel("small", 128, "")],
        steps=[1, 2],
        clips=1,
        repeats=repeats,
        out=tmp_path / "out",
        closed_loop=False,
        progress=False,
    )
    assert timed == [want, want]
    assert r["latency_repeats"] == want
