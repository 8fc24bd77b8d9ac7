"""PPI on run folders: outcomes read from a paired and an imagined-only run, metrics.json, the report, plan-trials."""

from __future__ import annotations

import json
import os
from pathlib import Path

import numpy as np
import pytest

from pilworld.bench.ppi import Population, evaluate_setting, run_ppi_bench, synthetic_rho
from pilworld.cli.main import main
from pilworld.data.outcomes import Outcome, read_outcomes, record_outcomes
from pilworld.data.reader import EpisodeStore
from pilworld.imagine.runner import ImagineConfig, imagine_run
from pilworld.paired import PairedConfig, paired_run
from pilworld.paired.record_starts import record_starts
from pilworld.ppi import ppi_mean
from pilworld.ppi.outcomes import read_run_outcomes
from pilworld.ppi.section import ppi_section
from pilworld.types import ChunkSpec
from simrig.files import SIM_RIG

CKPTS = ["scripted_step_30k", "scripted_step_01k"]
SPEC = ChunkSpec(rounds=1)


def _vision_verdicts(root: Path, pattern: list[bool]) -> None:
    """Deterministic image-only verdicts (the judge itself is tested in tests/pilworld/judges)."""
    store = EpisodeStore(root)
    out = [
        Outcome(i, "vision", "vision", pattern[i % len(pattern)], int(r["length"]))
        for i, r in enumerate(store.episodes)
    ]
    record_outcomes(root, out)


@pytest.fixture(scope="module")
def runs(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, Path]:
    os.environ.setdefault("MUJOCO_GL", "egl")
    base = tmp_path_factory.mktemp("ppi")
    paired = base / "paired"
    cfg = PairedConfig(
        rig=str(SIM_RIG), task="sort_cubes", checkpoints=CKPTS, subtasks=3, out=str(paired), seed=7_400_000, spec=SPEC
    )
    paired_run(cfg, progress=False)
    _vision_verdicts(paired, [True, True, False])
    starts = base / "starts"
    record_starts(str(SIM_RIG), "sort_cubes", 4, starts, seed=7_500_000, spec=SPEC, progress=False)
    imagined = base / "imagined"
    imagine_run(ImagineConfig(starts=str(starts), checkpoints=CKPTS, out=str(imagined)), progress=False)
    _vision_verdicts(imagined, [True, False])
    return paired, imagined


def test_outcomes_pair_the_checker_with_the_image_judge(runs: tuple[Path, Path]) -> None:
    paired, imagined = runs
    o = read_run_outcomes(paired, [str(imagined)])
    assert sorted(o.by_checkpoint) == sorted(CKPTS)
    for c in CKPTS:
        g = o.by_checkpoint[c]
        assert len(g.y) == len(g.f) == 3 and len(g.unlabeled) == 4
        assert g.gold_judges == {"sim_checker"}
    assert o.overlapping == 0
    # the paired run's own imagined branches are not unlabelled data: the same subtasks
    assert read_run_outcomes(paired, [str(paired)]).by_checkpoint[CKPTS[0]].unlabeled == []


def test_the_section_is_the_estimator_on_those_outcomes(runs: tuple[Path, Path]) -> None:
    paired, imagined = runs
    sec = ppi_section(paired, [str(imagined)])
    o = read_run_outcomes(paired, [str(imagined)])
    for c in CKPTS:
        want = ppi_mean(o.by_checkpoint[c].y, o.by_checkpoint[c].f, o.by_checkpoint[c].unlabeled).to_json()
        got = sec["checkpoints"][c]
        assert got["ppi"] == want["ppi"] and got["classical"] == want["classical"] and got["n"] == 3
    assert set(sec["ranking"]) == set(CKPTS) and len(sec["differences"]) == 1
    assert {s["task"] for s in sec["settings"]} == {"sort_cubes"}


def test_report_attaches_imagined_runs(runs: tuple[Path, Path], capsys: pytest.CaptureFixture[str]) -> None:
    paired, imagined = runs
    assert main(["report", str(paired), "--imagined", str(imagined), "--max-pairs", "0"]) == 0
    metrics = json.loads((paired / "metrics.json").read_text())
    assert metrics["ppi"]["checkpoints"][CKPTS[0]]["N"] == 4
    assert metrics["ppi"]["imagined_runs"] == [str(imagined.resolve())]
    html = (paired / "report.html").read_text()
    assert "Real success rate by PPI++" in html
    capsys.readouterr()


def test_imagined_branches_of_a_checkpoint_without_pairs_are_refused(
    runs: tuple[Path, Path], tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    paired, _ = runs
    starts = tmp_path / "starts"
    record_starts(str(SIM_RIG), "sort_cubes", 1, starts, seed=7_600_000, spec=SPEC, progress=False)
    other = tmp_path / "other"
    imagine_run(ImagineConfig(starts=str(starts), checkpoints=["scripted_step_05k"], out=str(other)), progress=False)
    _vision_verdicts(other, [True])
    before = {p.name: p.read_bytes() for p in paired.iterdir() if p.is_file()}
    assert main(["report", str(paired), "--imagined", str(other)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "scripted_step_05k" in err[0] and "n = 0" in err[0]
    assert {p.name: p.read_bytes() for p in paired.iterdir() if p.is_file()} == before  # nothing lost or changed


def test_plan_trials_reads_the_pilot(runs: tuple[Path, Path], capsys: pytest.CaptureFixture[str]) -> None:
    paired, _ = runs
    assert main(["plan-trials", str(paired), "--half-width", "0.1", "--json"]) == 0
    out = capsys.readouterr().out.strip().splitlines()
    plans = json.loads(out[-1])
    assert set(plans) == {*CKPTS, "all checkpoints"}
    for plan in plans.values():
        assert plan["pilot_pairs"] in (3, 6)
        assert plan["limit"] <= min(plan["with_imagined"].values()) <= plan["classical"]
    assert main(["plan-trials", str(paired), "--half-width", "0.7"]) == 2
    assert main(["plan-trials", str(paired.parent / "starts"), "--half-width", "0.1"]) == 2


def test_bench_coverage_and_formula_on_a_synthetic_population() -> None:
    rng = np.random.default_rng(3)
    pops = [Population(f"c{p}", (rng.random(200) < p).astype(float), np.zeros(200)) for p in (0.3, 0.6)]
    r = evaluate_setting(pops, "agreement_0.9", 20, 400, 1500, "wilson", seed=1)
    assert 0.93 <= r["coverage_ppi"] <= 0.97
    assert abs(r["width_ratio_vs_formula"] - 1) <= 0.1
    assert r["ess_gain_measured"] > 1.5
    assert synthetic_rho(0.5, 0.9) == pytest.approx(0.8)
    assert synthetic_rho(0.3, 0.5) == pytest.approx(0.0, abs=1e-12)


def test_bench_runs_on_a_judged_pool(runs: tuple[Path, Path]) -> None:
    paired, _ = runs
    r = run_ppi_bench(pool=paired, draws=20, progress=False)
    assert len(r["settings"]) == 2 * 4 * 3 * 2  # methods × predictors × n × N
    assert set(r["checks"]) >= {"coverage_in_band", "width_ratio_within_10pct", "ess_gain_agreement_0.9_n20_N400"}
    assert r["pool_pairs"] == {c: 3 for c in CKPTS}
    assert len(read_outcomes(paired)) > 0


def test_the_proxy_judge_follows_the_learned_judge_and_the_selection(
    runs: tuple[Path, Path], tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """Default proxy: the run's selected judge, else 'learned' where it judged, else 'vision'; --proxy-judge
    names one (refused in one line without its verdicts) and is remembered for later recomputations."""
    import shutil

    from pilworld.data.judge_selection import write_selection
    from pilworld.ppi.outcomes import default_proxy

    paired, imagined = (tmp_path / "paired", tmp_path / "imagined")
    shutil.copytree(runs[0], paired)
    shutil.copytree(runs[1], imagined)
    for f in (paired / "imagined_runs.json", paired / "metrics.json"):
        f.unlink(missing_ok=True)
    assert default_proxy(paired) == "vision"  # judged by the reference alone
    store = EpisodeStore(paired)
    record_outcomes(paired, [Outcome(i, "learned", "vision", i % 2 == 0, int(r["length"])) for i, r in
                             enumerate(store.episodes)])  # fmt: skip
    assert default_proxy(paired) == "learned"
    write_selection(paired, ["vision"], "a test")
    assert default_proxy(paired) == "vision" and ppi_section(paired)["proxy_judge"] == "vision"
    assert main(["report", str(paired), "--imagined", str(imagined), "--proxy-judge", "nobody"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "'nobody' has no verdicts" in err[0] and not (paired / "imagined_runs.json").exists()
    assert main(["report", str(paired), "--proxy-judge", "learned"]) == 2  # only with --imagined
    capsys.readouterr()
    args = ["report", str(paired), "--imagined", str(imagined), "--proxy-judge", "learned", "--max-pairs", "0"]
    assert main(args) == 0
    assert json.loads((paired / "metrics.json").read_text())["ppi"]["proxy_judge"] == "learned"
    assert default_proxy(paired) == "learned"  # remembered over the selection
    assert main(["report", str(paired), "--imagined", str(imagined), "--max-pairs", "0"]) == 0  # kept
    assert json.loads((paired / "metrics.json").read_text())["ppi"]["proxy_judge"] == "learned"
    capsys.readouterr()
