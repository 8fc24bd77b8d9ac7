"""The paired runner: same start in both branches, both origins stored, resumable with identical results."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from pilworld.cli.main import main
from pilworld.data.outcomes import read_outcomes
from pilworld.data.reader import EpisodeStore
from pilworld.paired import PairedConfig, paired_run
from pilworld.paired.runner import TIMINGS_FILE, PairedSubtask, plan_subtasks
from pilworld.types import ChunkSpec
from pilworld.world_model import V1_CHECKPOINT
from tests.pilworld.paired.digest import dataset_digest

SIM = "configs/rig/sim_dual_ur5e.yaml"
FAST = ChunkSpec(rounds=2)


def _cfg(out: Path, **kw: object) -> PairedConfig:
    args: dict[str, object] = {
        "rig": SIM,
        "task": "sort_cubes",
        "checkpoints": ["scripted_step_30k"],
        "subtasks": 2,
        "out": str(out),
        "spec": FAST,
    }
    args.update(kw)
    return PairedConfig(**args)  # type: ignore[arg-type]


@pytest.fixture(scope="module")
def full_run(tmp_path_factory: pytest.TempPathFactory) -> Path:
    out = tmp_path_factory.mktemp("paired") / "full"
    paired_run(_cfg(out), progress=False)
    return out


def test_both_origins_stored_with_byte_identical_starts(full_run: Path) -> None:
    store = EpisodeStore(full_run)
    assert store.num_episodes == 4
    eps = [store.load(i) for i in range(store.num_episodes)]
    assert [e.origin for e in eps] == ["imagined", "real", "imagined", "real"]
    for imagined, real in ((eps[0], eps[1]), (eps[2], eps[3])):
        assert imagined.extra["pair"] == real.extra["pair"]
        assert imagined.subtask_index == real.subtask_index and imagined.seed == real.seed
        assert imagined.length == real.length == 1 + FAST.rounds * FAST.frames
        for v in imagined.images:
            assert imagined.images[v][0].tobytes() == real.images[v][0].tobytes()
        np.testing.assert_array_equal(imagined.state[0], real.state[0])
        # The branches diverge after the start: the world model does not copy the robot.
        assert not np.array_equal(imagined.images["cam_high"][-1], real.images["cam_high"][-1])
    assert [e.subtask_index for e in eps] == [0, 0, 1, 1]
    verdicts = read_outcomes(full_run)
    assert sorted(o.episode_index for o in verdicts) == [1, 3]  # the simulator's checker judges the real branch
    timings = [json.loads(line) for line in (full_run / TIMINGS_FILE).read_text().splitlines()]
    assert [t["origin"] for t in timings] == ["imagined", "real", "imagined", "real"]
    assert all(len(t["policy_ms"]) == len(t["env_ms"]) == FAST.rounds for t in timings)


def test_interrupted_run_resumes_to_the_same_dataset(full_run: Path, tmp_path: Path) -> None:
    out = tmp_path / "resumed"
    calls: list[str] = []

    def stop_after_three(pair: PairedSubtask, origin: str) -> None:
        calls.append(origin)
        if len(calls) == 3:
            raise KeyboardInterrupt

    with pytest.raises(KeyboardInterrupt):
        paired_run(_cfg(out), progress=False, on_branch=stop_after_three)
    assert EpisodeStore(out).num_episodes == 3
    summary = paired_run(_cfg(out), progress=False)
    assert summary["branches_run"] == 1  # only the missing real branch of the second subtask
    assert dataset_digest(out) == dataset_digest(full_run)
    again = paired_run(_cfg(out), progress=False)
    assert again["branches_run"] == 0


def test_resume_refuses_other_settings(full_run: Path) -> None:
    with pytest.raises(ValueError, match=r"different settings.*task"):
        paired_run(_cfg(full_run, task="stack_blocks"), progress=False)


def test_plan_walks_subtasks_then_seeds() -> None:
    plan = plan_subtasks("sort_cubes", 5, 10, ["a", "b"], num_subtasks=3, instruction="x")
    assert [(p.checkpoint, p.subtask.seed, p.subtask.index) for p in plan[:5]] == [
        ("a", 10, 0),
        ("a", 10, 1),
        ("a", 10, 2),
        ("a", 11, 0),
        ("a", 11, 1),
    ]
    assert len({p.pair_id for p in plan}) == 10


def test_config_errors_are_clear(tmp_path: Path) -> None:
    with pytest.raises(ValueError, match="subtasks"):
        _cfg(tmp_path, subtasks=0)
    with pytest.raises(ValueError, match="listed twice"):
        _cfg(tmp_path, checkpoints=["a", "a"])
    with pytest.raises(ValueError, match="not a scripted checkpoint"):
        paired_run(_cfg(tmp_path / "x", checkpoints=["no_such_ckpt"]), progress=False)


def test_cli_runs_and_data_info_shows_both_origins(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    out = tmp_path / "cli"
    rc = main(
        [
            "paired",
            "run",
            "--rig",
            SIM,
            "--task",
            "sort_cubes",
            "--subtasks",
            "1",
            "--rounds",
            "1",
            "--out",
            str(out),
            "--json",
        ]
    )
    assert rc == 0
    summary = json.loads(capsys.readouterr().out.strip().splitlines()[-1])
    assert set(summary["seconds_per_subtask"]) == {"imagined", "real"}
    assert main(["data", "info", str(out), "--json"]) == 0
    info = json.loads(capsys.readouterr().out.strip().splitlines()[-1])
    assert set(info["by_origin"]) == {"imagined", "real"}
    assert main(["paired", "run", "--task", "juggle", "--subtasks", "1", "--out", str(out)]) == 2
    assert "unknown task" in capsys.readouterr().err


def test_a_policy_served_over_openpi_gives_the_local_result(tmp_path: Path) -> None:
    """The same scripted checkpoint, local and behind the loopback openpi server: identical branches."""
    from pilworld.config.rig import RigConfig
    from pilworld.policies.openpi.server import PolicyServer
    from pilworld.policies.scripted import ScriptedPolicy

    one = ChunkSpec(rounds=1)
    local = tmp_path / "local"
    paired_run(_cfg(local, subtasks=1, spec=one), progress=False)
    rig = RigConfig.load(SIM)
    size = (rig.image_size.height, rig.image_size.width)  # announced, so the client sends native images
    with PolicyServer(ScriptedPolicy(rig, "scripted_step_30k"), image_size=size) as server:
        remote = tmp_path / "remote"
        paired_run(_cfg(remote, subtasks=1, spec=one, checkpoints=[server.url]), progress=False)
    a, b = EpisodeStore(local), EpisodeStore(remote)
    assert a.num_episodes == b.num_episodes == 2
    for i in range(2):
        ea, eb = a.load(i), b.load(i)
        assert ea.origin == eb.origin and eb.checkpoint == server.url
        np.testing.assert_array_equal(ea.action, eb.action)
        for v in ea.images:
            np.testing.assert_array_equal(ea.images[v], eb.images[v])


def test_several_tasks_in_one_run(tmp_path: Path) -> None:
    out = tmp_path / "multi"
    summary = paired_run(
        _cfg(
            out,
            task="stack_blocks,sort_cubes",
            subtasks=1,
            spec=ChunkSpec(rounds=1),
            world_model=str(V1_CHECKPOINT),  # v1 has a stage-2 adapter per task
        ),
        progress=False,
    )
    assert summary["pairs_planned"] == 2
    eps = EpisodeStore(out).episodes
    tasks = [json.loads(e["extra"])["sim_task"] for e in eps]
    assert tasks == ["stack_blocks", "stack_blocks", "sort_cubes", "sort_cubes"]
    adapters = {json.loads(e["extra"])["adapter"] for e in eps}
    assert adapters == {"stack_blocks", "sort_cubes"}  # each task's own stage-2 adapter
    with pytest.raises(ValueError, match="unknown task"):
        paired_run(_cfg(tmp_path / "bad", task="sort_cubes,juggle"), progress=False)
