"""``pilworld sim collect --task FILE``: a task file collected like a packaged task, its episodes naming the
task and its file hash; a refused collection leaves its folder untouched."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from pilworld.cli.main import main
from pilworld.collection.collect import collect, summarize
from pilworld.collection.evaluate import success_rates
from pilworld.collection.tasks import episode_task_name, resolve_tasks, task_extra
from pilworld.data.reader import EpisodeStore
from pilworld.policies.scripted import BEST_CHECKPOINT
from pilworld.types import ChunkSpec
from simrig.tasks import PAPER_TASKS, load_task

ROOT = Path(__file__).resolve().parents[3]
SIM = str(ROOT / "configs" / "rig" / "sim_dual_ur5e.yaml")
PACKAGED = ROOT / "configs" / "tasks" / "stack_blocks.yaml"  # 2 subtasks: the cheapest to run whole
SHORT = ChunkSpec(rounds=1)


def _copy(tmp_path: Path, name: str) -> Path:
    path = tmp_path / f"{name}.yaml"
    path.write_text(PACKAGED.read_text(encoding="utf-8").replace("name: stack_blocks", f"name: {name}"), "utf-8")
    return path


def test_a_task_file_is_collected_under_its_own_name(tmp_path: Path) -> None:
    task = _copy(tmp_path, "my_blocks")
    out = tmp_path / "data"
    summary = collect(
        out,
        rig_path=SIM,
        tasks=[task],
        checkpoints=[BEST_CHECKPOINT],
        episodes=1,
        workers=1,
        spec=SHORT,
        progress=False,
        instruction="stack the blocks.",
    )
    assert summary["episodes"] == 2 and set(summary["per_task"]) == {"my_blocks"}
    store = EpisodeStore(out)
    digest = load_task(task).digest
    for i in range(store.num_episodes):
        ep = store.load(i)
        assert ep.extra["task"] == ep.extra["sim_task"] == "my_blocks" and ep.extra["task_sha256"] == digest
        assert ep.extra["run"].startswith("my_blocks/") and ep.task == "stack the blocks."
    again = collect(out, rig_path=SIM, tasks=[task], checkpoints=[BEST_CHECKPOINT], episodes=1, workers=1, spec=SHORT)
    assert again["runs_simulated"] == 0 and summarize(out)["episodes"] == 2  # resumed: nothing to do


@pytest.mark.parametrize(
    "argv, flag",
    [
        (["--task", "nowhere.yaml"], "--task"),
        (["--task", "sort_cubes,sort_cubes"], "--task"),
        (["--checkpoint", "scripted_step_99k"], "--checkpoint"),
        (["--instruction", "  "], "--instruction"),
    ],
)
def test_a_refused_collection_leaves_its_folder_untouched(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], argv: list[str], flag: str
) -> None:
    out = tmp_path / "data"
    base = ["sim", "collect", "--episodes", "1", "--out", str(out), "--workers", "1"]
    assert main([*base, *argv]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith(f"pilworld: error: {flag}:"), err
    assert not out.exists()


def test_all_means_the_paper_tasks_and_readers_fall_back_to_sim_task(tmp_path: Path) -> None:
    assert [t.name for t in resolve_tasks("all")] == list(PAPER_TASKS)
    assert episode_task_name({"task": "pour", "sim_task": "x"}) == "pour"
    assert episode_task_name({"sim_task": "sort_cubes"}) == "sort_cubes"
    assert episode_task_name({}, "?") == "?"
    pour = tmp_path / "pour.yaml"
    pour.write_text('name: pour\ninstruction: "pour."\nsubtasks: [{operator_setup: "a cup"}]\n', encoding="utf-8")
    extra = task_extra(load_task(pour))
    assert extra == {"task": "pour", "task_sha256": load_task(pour).digest}  # no sim_task: not simulated


def test_success_rates_take_a_task_file(tmp_path: Path) -> None:
    task = _copy(tmp_path, "my_blocks")
    rates = success_rates(SIM, [task], [BEST_CHECKPOINT], 1, workers=1, spec=SHORT, progress=False)
    assert list(rates) == ["my_blocks"] and 0.0 <= rates["my_blocks"][BEST_CHECKPOINT] <= 1.0
    assert json.dumps(rates)
