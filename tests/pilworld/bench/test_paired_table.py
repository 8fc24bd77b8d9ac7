"""``pilworld bench paired``: variant selection, the protocol, failure faithfulness, the table's JSON on a
one-pair protocol (the second variant copying the first's real branches) and its chart.
"""

from __future__ import annotations

import contextlib
import dataclasses
import io
import json
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest

from pilworld.bench import paired as bench
from pilworld.bench.charts import paired_table_chart
from pilworld.bench.paired import (
    QUICK_CHECKPOINTS,
    TARGETS,
    failure_faithfulness,
    protocol,
    run_paired_bench,
    select_variants,
)
from pilworld.bench.variants import V2_VARIANTS, ModelVariant, PairedProtocol, evaluate_variants, standard_variants
from pilworld.cli.main import main
from pilworld.data.outcomes import Outcome, record_outcomes
from pilworld.data.reader import EpisodeStore
from pilworld.paired.runner import TIMINGS_FILE
from pilworld.policies.registry import policy_names
from pilworld.world_model import V1_CHECKPOINT
from simrig.files import SIM_RIG as DEFAULT_RIG
from simrig.tasks import TASK_NAMES
from tests.pilworld.metrics.synthetic import ROUNDS, K, SynthPair, write_paired

SIM = "configs/rig/sim_dual_ur5e.yaml"
PNG = b"\x89PNG\r\n\x1a\n"
ONE_PAIR = PairedProtocol(tasks=("sort_cubes",), checkpoints=("scripted_step_30k",), subtasks=1, rounds=1)


def _one_pair(
    quick: bool, *, subtasks: int | None = None, seed: int | None = None, rounds: int = 5, judge: str = ""
) -> PairedProtocol:
    return dataclasses.replace(ONE_PAIR, judge=judge)


# ---------------------------------------------------------------------- variants and protocol


def test_the_equal_budget_v2_variants_are_selectable_and_name_their_training_command(
    monkeypatch: pytest.MonkeyPatch, tmp_path: Path
) -> None:
    from pilworld.bench import variants as variants_module
    from pilworld.bench.variants import v2_variants

    names = [v.name for v in v2_variants()]
    assert names == [n for n, _, _ in V2_VARIANTS] and len(set(names)) == len(names) == 8
    assert not set(names) & {v.name for v in standard_variants()}
    monkeypatch.setattr(variants_module, "BENCH_WEIGHTS", tmp_path)  # no weights there
    chosen = select_variants(True, ["v2_render"])
    assert [v.name for v in chosen] == ["pilworld", "v2_render"] and chosen[1].adapter == "none"
    with pytest.raises(FileNotFoundError, match=r"make it with scripts/train-bench-variants v2_render"):
        chosen[1].check()
    with pytest.raises(ValueError, match="standard variant's name"):
        select_variants(True, ["v2_render=/some/model"])


def test_select_variants_by_mode_and_by_name() -> None:
    assert [v.name for v in select_variants(True)] == ["pilworld", "v2_paper_gamma", "v2_ctrl_world"]
    full = select_variants(False)  # the shipped v2 and its eight equal-budget variants (docs/RESULTS.md, section 1)
    assert [v.name for v in full] == ["pilworld"] + [n for n, _, _ in V2_VARIANTS]
    assert all(v.world_model.endswith(f"weights/bench/{v.name}") for v in full[1:])
    assert [v.name for v in full if v.role == "baseline"] == ["v2_paper_gamma", "v2_ctrl_world"]
    for v in full:
        v.check()  # every weights folder is committed
    # v1 and its 2026-11-22 baselines stay selectable by name.
    assert [v.name for v in select_variants(False, ["pilworld_v1"])] == ["pilworld", "pilworld_v1"]
    # The shipped model is always there (first when not named), named variants keep their order.
    assert [v.name for v in select_variants(True, ["no_history"])] == ["pilworld", "no_history"]
    assert [v.name for v in select_variants(False, ["success_only", "no_history"])] == [
        "pilworld",
        "success_only",
        "no_history",
    ]
    assert [v.name for v in select_variants(True, ["ctrl_world", "pilworld"])] == ["ctrl_world", "pilworld"]
    no_history = select_variants(True, ["no_history"])[1]
    assert no_history.history is False and no_history.world_model == str(V1_CHECKPOINT)
    assert no_history.role == "ablation"
    with pytest.raises(ValueError, match=r"unknown \['bogus'\]"):
        select_variants(True, ["no_history", "bogus"])


def test_protocol_values() -> None:
    quick = protocol(True)
    assert quick.tasks == tuple(TASK_NAMES) and len(quick.tasks) == 3
    assert quick.checkpoints == QUICK_CHECKPOINTS == ("scripted_step_01k", "scripted_step_30k")
    assert (quick.subtasks, quick.rounds, quick.seed, quick.pairs) == (3, 5, 6_000_000, 18)
    full = protocol(False)
    assert full.checkpoints == tuple(policy_names()) and len(full.checkpoints) == 5
    assert (full.subtasks, full.rounds, full.seed, full.pairs) == (8, 5, 6_000_000, 120)
    custom = protocol(True, subtasks=2, seed=7, rounds=3)
    assert (custom.subtasks, custom.seed, custom.rounds, custom.checkpoints) == (2, 7, 3, QUICK_CHECKPOINTS)


def test_a_missing_variant_model_fails_before_any_run(tmp_path: Path) -> None:
    missing = ModelVariant("other", "a model not trained yet", str(tmp_path / "nowhere"), adapter="none")
    shipped = standard_variants()[0]
    with pytest.raises(FileNotFoundError, match="variant 'other'"):
        evaluate_variants([shipped, missing], ONE_PAIR, tmp_path / "out", rig=SIM, progress=False)
    assert not (tmp_path / "out").exists()
    with pytest.raises(ValueError, match="listed twice"):
        evaluate_variants([shipped, shipped], ONE_PAIR, tmp_path / "out", rig=SIM, progress=False)


def test_failure_faithfulness(tmp_path: Path) -> None:
    """Of 3 real failures 2 also fail imagined; of 2 real successes 1 also succeeds; unjudged pairs skipped."""
    plan = [(0, 0), (0, 0), (0, 1), (1, 1), (1, 0), (None, None)]
    root = write_paired(tmp_path / "run", [SynthPair(subtask=i) for i in range(len(plan))])
    T = 1 + ROUNDS * K
    verdicts = []
    for i, (real, imag) in enumerate(plan):
        if real is None or imag is None:
            continue
        verdicts.append(Outcome(2 * i, "vision", "vision", bool(imag), T))
        verdicts.append(Outcome(2 * i + 1, "vision", "vision", bool(real), T))
        verdicts.append(Outcome(2 * i + 1, "sim_checker", "sim_state", not real, T))  # not a both-branch judge
    record_outcomes(root, verdicts)
    ff = failure_faithfulness(str(root))
    assert ff == {
        "real_failures": 3,
        "imagined_also_failed": pytest.approx(2 / 3),
        "real_successes": 2,
        "imagined_also_succeeded": 0.5,
    }
    empty = write_paired(tmp_path / "empty", [SynthPair()])
    assert failure_faithfulness(str(empty)) == {
        "real_failures": 0,
        "imagined_also_failed": None,
        "real_successes": 0,
        "imagined_also_succeeded": None,
    }


def test_cli_rejects_bad_arguments(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["bench", "paired", "--subtasks", "0", "--out", str(tmp_path / "a")]) == 2
    assert "--subtasks" in capsys.readouterr().err
    assert main(["bench", "paired", "--variants", "pilworld,bogus", "--out", str(tmp_path / "b")]) == 2
    assert "bogus" in capsys.readouterr().err
    assert not (tmp_path / "a").exists() and not (tmp_path / "b").exists()


# ---------------------------------------------------------------------- the table on one pair


@pytest.fixture(scope="module")
def table(tmp_path_factory: pytest.TempPathFactory) -> Iterator[tuple[Path, dict[str, Any], str]]:
    """``pilworld bench paired --variants pilworld,no_history --json`` on a one-pair protocol."""
    out = tmp_path_factory.mktemp("paired_table") / "b"
    buf = io.StringIO()
    with pytest.MonkeyPatch.context() as mp, contextlib.redirect_stdout(buf):
        mp.setattr(bench, "protocol", _one_pair)
        rc = main(
            ["bench", "paired", "--variants", "pilworld,no_history", "--out", str(out), "--workers", "1", "--json"]
        )
    assert rc == 0
    stdout = buf.getvalue()
    yield out, json.loads(stdout.strip().splitlines()[-1]), stdout


def test_sr_comes_from_the_shipped_learned_judge_with_the_reference_beside_it(
    table: tuple[Path, dict[str, Any], str],
) -> None:
    from pilworld.judges.learned.shipped import SHIPPED_JUDGE

    out, r, stdout = table
    assert str(SHIPPED_JUDGE) in r["protocol"]["judge"]
    for name in ("pilworld", "no_history"):
        row = r["judges"][name]
        assert row["selection"]["judges"] == ["learned"] and row["learned"]["folder"] == str(SHIPPED_JUDGE)
        assert set(row["per_judge"]) == {"learned", "vision"} or set(row["per_judge"]) == {"vision"}  # all abstained
        metrics = json.loads((out / name / "metrics.json").read_text())
        assert metrics["judges"]["selection"]["set_by"] == "pilworld bench"
    assert "by judge (SR_real/SR_imag %, * counts)" in stdout and "vision " in stdout


def test_table_json_has_the_headline_figures(table: tuple[Path, dict[str, Any], str]) -> None:
    out, r, _ = table
    assert r["bench"] == "paired" and r["quick"] is False
    assert r["protocol"]["pairs_per_variant"] == 1 and r["protocol"]["rounds"] == 1
    assert r["protocol"]["tasks"] == ["sort_cubes"]
    for key in ("abs_delta_sr", "hfr", "pearson", "mmrv", "sr_real", "sr_imag", "ranking_ci95"):
        assert key in r["overall"], key
    assert r["overall"]["n_subtasks"] == 1 and r["overall"]["n_settings"] == 1
    assert r["overall"]["pearson"] is None and "fewer than 2" in r["overall"]["pearson_reason"]
    assert 0.0 <= r["overall"]["abs_delta_sr"] <= 1.0 and 0.0 <= r["overall"]["hfr"] <= 1.0
    assert r["overall"]["ranking_ci95"]["reason"].startswith("fewer than 2 settings")
    assert list(r["variants"]) == ["pilworld", "no_history"]
    assert r["overall"] == r["variants"]["pilworld"]["overall"]  # the headline is the shipped model's
    assert r["baseline"] is None  # no baseline variant chosen
    assert r["claims"] == []  # no claim's two variants were run
    assert r["gamma_plus_rows"] == ["pilworld"]
    assert r["targets"] == TARGETS
    assert r["chart"] == str(out / "paired.png")


def test_each_variant_row(table: tuple[Path, dict[str, Any], str]) -> None:
    out, r, _ = table
    ours, ablation = r["variants"]["pilworld"], r["variants"]["no_history"]
    assert ours["role"] == "shipped" and ablation["role"] == "ablation"
    assert ablation["world_model"] == str(V1_CHECKPOINT) and ablation["out"] == str(out / "no_history")
    assert ablation["settings"] == [
        {
            "task": "sort_cubes",
            "checkpoint": "scripted_step_30k",
            "sr_real": ablation["overall"]["sr_real"],
            "sr_imag": ablation["overall"]["sr_imag"],
            "hfr": ablation["overall"]["hfr"],
            "n": 1,
        }
    ]
    # Both variants judge the same (copied) real branch.
    for key in ("sr_real", "sr_real_checker"):
        assert ours["overall"][key] == ablation["overall"][key], key
    for row in (ours, ablation):
        ff = row["failure_faithfulness"]
        assert ff["real_failures"] + ff["real_successes"] == 1
        agree = row["agreement"]
        assert agree["successes"]["n"] + agree["failures"]["n"] == 1 and agree["all"]["n"] == 1
        assert agree["successes"]["n"] == ff["real_successes"]
        assert list(agree["tasks"]) == ["sort_cubes"]
        assert set(row["single_step"]["per_view"]) == {"cam_high", "cam_left_wrist", "cam_right_wrist"}
        assert row["single_step"]["pairs_used"] == 1
        assert row["imagined_seconds_per_subtask"]["n"] == 1
    # Same start and policy, the memory hidden: the first round's frames differ.
    assert ours["single_step"]["per_view"]["cam_high"] != ablation["single_step"]["per_view"]["cam_high"]


def test_the_ablation_copies_the_real_branch(table: tuple[Path, dict[str, Any], str]) -> None:
    out, _, _ = table
    ours, ablation = EpisodeStore(out / "pilworld"), EpisodeStore(out / "no_history")
    real_ours = next(ours.load(i) for i in range(ours.num_episodes) if ours.load(i).origin == "real")
    real_abl = next(ablation.load(i) for i in range(ablation.num_episodes) if ablation.load(i).origin == "real")
    assert "real_from" not in real_ours.extra
    assert real_abl.extra["real_from"] == str(out / "pilworld")
    for v in real_ours.images:
        assert real_ours.images[v].tobytes() == real_abl.images[v].tobytes(), v
    timings = (out / "no_history" / TIMINGS_FILE).read_text().splitlines()
    assert [json.loads(t)["origin"] for t in timings] == ["imagined"]
    for name in ("pilworld", "no_history"):
        assert (out / name / "metrics.json").is_file() and (out / name / "variant_result.json").is_file()


def test_printed_table_and_chart(table: tuple[Path, dict[str, Any], str], tmp_path: Path) -> None:
    out, r, stdout = table
    lines = stdout.splitlines()
    assert any(line.strip().startswith("pilworld ") for line in lines)
    assert any(line.strip().startswith("no_history ") for line in lines)
    assert "1 tasks × 1 checkpoints × 1 subtasks, R=1" in stdout
    assert (out / "paired.png").read_bytes()[:8] == PNG
    redrawn = paired_table_chart(r["variants"], r["targets"], tmp_path / "sub" / "again.png")
    assert redrawn == tmp_path / "sub" / "again.png" and redrawn.read_bytes()[:8] == PNG


def test_rerun_resumes_everything(table: tuple[Path, dict[str, Any], str], monkeypatch: pytest.MonkeyPatch) -> None:
    """The same call again runs no branch and gives the same figures."""
    out, r, _ = table
    monkeypatch.setattr(bench, "protocol", _one_pair)
    # The rig as the CLI passed it: runs compare the rig path as written.
    again = run_paired_bench(out=out, rig=DEFAULT_RIG, variants=["no_history"], workers=1, progress=False)
    assert list(again["variants"]) == ["pilworld", "no_history"]
    for name in ("pilworld", "no_history"):
        assert again["variants"][name]["overall"] == r["variants"][name]["overall"], name
        assert EpisodeStore(out / name).num_episodes == 2
    assert len((out / "no_history" / TIMINGS_FILE).read_text().splitlines()) == 1


def test_chart_with_missing_values(tmp_path: Path) -> None:
    """Undefined figures (None, no intervals, no settings) still draw."""
    variants: dict[str, dict[str, Any]] = {
        "a": {
            "overall": {"abs_delta_sr": 0.1, "hfr": 0.8, "ci95": {"abs_delta_sr": [0.05, 0.2], "hfr": [0.7, 0.9]}},
            "settings": [{"sr_real": 0.5, "sr_imag": 0.4}, {"sr_real": None, "sr_imag": None}],
        },
        "b": {"overall": {"abs_delta_sr": None, "hfr": None, "ci95": None}, "settings": []},
    }
    path = paired_table_chart(variants, TARGETS, tmp_path / "t.png")
    assert path.read_bytes()[:8] == PNG


def test_a_model_folder_runs_as_a_named_variant(tmp_path: Path) -> None:
    from pilworld.world_model import DEFAULT_CHECKPOINT

    chosen = select_variants(False, ["pilworld_v1", f"mine={DEFAULT_CHECKPOINT}"])
    assert [v.name for v in chosen] == ["pilworld", "pilworld_v1", "mine"]
    assert chosen[2].world_model == str(DEFAULT_CHECKPOINT) and chosen[2].adapter == "none"
    with pytest.raises(FileNotFoundError, match="mine"):
        select_variants(False, [f"mine={tmp_path}"])  # no config.json there
    with pytest.raises(ValueError, match="standard variant"):
        select_variants(False, [f"ctrl_world={DEFAULT_CHECKPOINT}"])
    with pytest.raises(ValueError, match="NAME=PATH"):
        select_variants(False, ["=x"])
    with pytest.raises(ValueError, match="twice"):
        select_variants(False, [f"a={DEFAULT_CHECKPOINT}", f"a={DEFAULT_CHECKPOINT}"])
