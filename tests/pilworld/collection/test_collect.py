"""Sim data collection end to end: what is stored (frames at the stride, stride-aligned actions, the
checker's verdicts), that it matches an independent closed-loop run bit for bit, resuming, and the
``pilworld sim`` / ``pilworld bench sim`` commands."""

from __future__ import annotations

import json
import shutil
from collections import Counter
from pathlib import Path
from typing import Any

import cv2
import numpy as np
import pytest

import pilworld.collection.collect as collect_mod
from pilworld.cli.main import main
from pilworld.collection.collect import JUDGE_ID, collect, summarize
from pilworld.collection.rollout import SubtaskRecording, run_subtask
from pilworld.data.outcomes import read_outcomes
from pilworld.data.reader import EpisodeStore
from pilworld.policies.scripted import BEST_CHECKPOINT, CHECKPOINTS, ScriptedPolicy
from pilworld.types import ChunkSpec
from simrig.robot import SimRobot
from simrig.tasks import TASK_NAMES

ROOT = Path(__file__).resolve().parents[3]
SIM = ROOT / "configs" / "rig" / "sim_dual_ur5e.yaml"
WORST = CHECKPOINTS[0].name
TASK = "stack_blocks"  # 2 subtasks: the cheapest task to run whole
SPEC = ChunkSpec()
FRAMES = 1 + SPEC.rounds * SPEC.frames  # the start, then K frames per round: 76


def _collect(root: Path, checkpoints: list[str], episodes: int) -> dict[str, Any]:
    return collect(
        root, rig_path=str(SIM), tasks=[TASK], checkpoints=checkpoints, episodes=episodes, workers=1, progress=False
    )


def _run_parts(store: EpisodeStore) -> list[tuple[str, int]]:
    return [(json.loads(e["extra"])["run"], int(e["subtask_index"])) for e in store.episodes]


@pytest.fixture(scope="module")
def collected(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, dict[str, Any]]:
    """One run of the best and one of the worst checkpoint on stack_blocks (4 subtask episodes)."""
    root = tmp_path_factory.mktemp("sim_collect") / "dataset"
    return root, _collect(root, [BEST_CHECKPOINT, WORST], episodes=1)


@pytest.fixture(scope="module")
def independent_run() -> list[SubtaskRecording]:
    """The best checkpoint's run of seed 0, simulated again on a fresh robot the way collection does it."""
    with SimRobot(SIM, TASK) as robot:
        policy = ScriptedPolicy(robot.rig, BEST_CHECKPOINT, horizon=SPEC.horizon)
        start = robot.reset(seed=0, subtask=0, history=SPEC.history, stride=SPEC.stride)
        obs = start.observation
        recs = []
        policy.reset(seed=0)  # one continuous episode: the policy is reset once per run
        for k in range(robot.task.num_subtasks):
            recs.append(run_subtask(robot, policy.infer, obs, robot.task.instruction, spec=SPEC, subtask_index=k))
            obs = robot.observe()
    return recs


# ---------------------------------------------------------------------- what is stored


def test_collect_stores_one_episode_per_subtask(collected: tuple[Path, dict[str, Any]]) -> None:
    root, summary = collected
    store = EpisodeStore(root)
    assert store.num_episodes == 4 and summary["episodes"] == 4
    assert store.fps == 10  # 30 Hz control / stride 3
    assert summary["runs_planned"] == 2 and summary["runs_simulated"] == 2 and summary["parts_written"] == 4
    assert summary["frames"] == 4 * FRAMES == store.num_frames
    assert _run_parts(store) == [
        (f"{TASK}/{BEST_CHECKPOINT}/0", 0),
        (f"{TASK}/{BEST_CHECKPOINT}/0", 1),
        (f"{TASK}/{WORST}/0", 0),
        (f"{TASK}/{WORST}/0", 1),
    ]
    for i, row in enumerate(store.episodes):
        assert int(row["length"]) == FRAMES
        table = store.frame_table(i)
        labels = store.labels(i, table)
        assert labels["task"] == "pick up the blocks and stack them one by one."
        assert labels["checkpoint"] in (BEST_CHECKPOINT, WORST) and labels["seed"] == 0
        assert labels["extra"]["sim_task"] == TASK and labels["extra"]["parts"] == 2
        rounds = labels["round_index"]
        assert rounds is not None and rounds[0] == 0 and rounds[-1] == SPEC.rounds - 1
        assert Counter(rounds.tolist()) == {0: 1 + SPEC.frames, **{r: SPEC.frames for r in range(1, SPEC.rounds)}}
    frames = store.frames(0, "cam_high")
    assert frames.shape == (FRAMES, 128, 128, 3)


def test_collected_clips_use_the_paper_stride_in_stored_frames(collected: tuple[Path, dict[str, Any]]) -> None:
    from pilworld.data.clip_dataset import ClipDataset

    root, _ = collected
    store = EpisodeStore(root)
    assert store.spec.steps_per_frame == SPEC.stride  # every Δ-th control step is stored
    clips = ClipDataset(root, cache_dir=root / "cache")
    assert clips.spec.stride == 1 and clips.spec.future == 15 and clips.spec.window == 9
    # 76 frames: clips start every 9 stored frames while 15 future frames fit: t = 0, 9, …, 54.
    assert len(clips) == 4 * len(range(0, FRAMES - 15, 9))
    item = clips[1]
    assert item["future"].shape == (3, 15, 3, 128, 128) and item["actions"].shape == (15, 14)


def test_outcomes_are_the_checkers_verdicts(collected: tuple[Path, dict[str, Any]]) -> None:
    root, summary = collected
    outcomes = read_outcomes(root)
    assert [o.episode_index for o in outcomes] == [0, 1, 2, 3]
    assert all(o.judge_id == JUDGE_ID == "sim_checker" and o.judge_kind == "sim_state" for o in outcomes)
    assert all(o.num_frames == FRAMES and o.first_hallucination_frame is None for o in outcomes)
    store = EpisodeStore(root)
    for o in outcomes:
        reason = json.loads(store.episodes[o.episode_index]["extra"])["checker"]
        assert reason  # the checker's human-readable reason travels with the episode
    # summarize() counts exactly the recorded verdicts, per task and checkpoint.
    again = summarize(root)
    assert again["per_task"] == summary["per_task"]
    assert again["success"] == sum(o.success for o in outcomes) == summary["success"]
    assert again["failure"] == sum(not o.success for o in outcomes) == summary["failure"]
    for ckpt in (BEST_CHECKPOINT, WORST):
        wins = sum(o.success for o in outcomes if store.episodes[o.episode_index]["checkpoint"] == ckpt)
        assert again["per_task"][TASK][ckpt] == {"success": wins, "failure": 2 - wins}
    assert again["bytes"] > 0 and again["frames"] == 4 * FRAMES


def test_stored_run_matches_an_independent_run(
    collected: tuple[Path, dict[str, Any]], independent_run: list[SubtaskRecording]
) -> None:
    root, _ = collected
    store = EpisodeStore(root)
    outcomes = {o.episode_index: o.success for o in read_outcomes(root)}
    for k, rec in enumerate(independent_run):  # episodes 0 and 1: the best checkpoint's run
        ep = store.load(k, views=["cam_high"])
        assert rec.length == FRAMES and len(rec.commands) == SPEC.rounds * SPEC.executed_steps
        # The simulator is deterministic: states are bit-exact, on another robot instance.
        np.testing.assert_array_equal(ep.state, np.stack(rec.states))
        np.testing.assert_array_equal(ep.action, np.stack(rec.actions))
        # action[i] is the stride-aligned command a[(i+1)Δ − 1] that leads to frame i + 1 …
        commands = np.stack(rec.commands)
        np.testing.assert_array_equal(ep.action[:-1], commands[SPEC.stride - 1 :: SPEC.stride])
        # … and the last frame repeats the last command.
        np.testing.assert_array_equal(ep.action[-1], commands[-1])
        assert rec.check is not None and outcomes[k] == rec.check.success
        # Images are stored lossy (h264) but are the same frames.
        diff = np.abs(ep.images["cam_high"].astype(np.int16) - np.stack(rec.images["cam_high"]).astype(np.int16))
        assert diff.mean() < 3.0


# ---------------------------------------------------------------------- resuming


def test_collect_again_simulates_nothing(collected: tuple[Path, dict[str, Any]], tmp_path: Path) -> None:
    root = tmp_path / "copy"
    shutil.copytree(collected[0], root)
    summary = _collect(root, [BEST_CHECKPOINT, WORST], episodes=1)
    assert summary["runs_planned"] == 2 and summary["runs_simulated"] == 0 and summary["parts_written"] == 0
    assert summary["episodes"] == 4 and len(read_outcomes(root)) == 4


def test_more_episodes_simulate_only_the_new_run(collected: tuple[Path, dict[str, Any]], tmp_path: Path) -> None:
    root = tmp_path / "copy"
    shutil.copytree(collected[0], root)
    summary = _collect(root, [BEST_CHECKPOINT], episodes=2)
    assert summary["runs_planned"] == 2 and summary["runs_simulated"] == 1 and summary["parts_written"] == 2
    store = EpisodeStore(root)
    assert store.num_episodes == 6
    assert _run_parts(store)[4:] == [(f"{TASK}/{BEST_CHECKPOINT}/1", 0), (f"{TASK}/{BEST_CHECKPOINT}/1", 1)]
    assert [o.episode_index for o in read_outcomes(root)] == list(range(6))


def test_a_killed_run_is_completed_without_duplicates(
    collected: tuple[Path, dict[str, Any]], tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    root = tmp_path / "copy"
    shutil.copytree(collected[0], root)
    simulate = collect_mod.simulate_run

    def killed_after_first_part(rig_path: str, job: Any, spec: ChunkSpec) -> list[Any]:
        return simulate(rig_path, job, spec)[:1]  # the process died after writing subtask 0

    monkeypatch.setattr(collect_mod, "simulate_run", killed_after_first_part)
    partial = _collect(root, [BEST_CHECKPOINT], episodes=2)
    assert partial["runs_simulated"] == 1 and partial["parts_written"] == 1 and partial["episodes"] == 5
    monkeypatch.setattr(collect_mod, "simulate_run", simulate)

    resumed = _collect(root, [BEST_CHECKPOINT], episodes=2)
    assert resumed["runs_simulated"] == 1 and resumed["parts_written"] == 1 and resumed["episodes"] == 6
    store = EpisodeStore(root)
    parts = _run_parts(store)
    assert len(parts) == len(set(parts)) == 6
    assert parts[4:] == [(f"{TASK}/{BEST_CHECKPOINT}/1", 0), (f"{TASK}/{BEST_CHECKPOINT}/1", 1)]
    assert [o.episode_index for o in read_outcomes(root)] == list(range(6))
    assert _collect(root, [BEST_CHECKPOINT], episodes=2)["runs_simulated"] == 0


# ---------------------------------------------------------------------- the CLI


def test_sim_show_writes_the_three_views(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    out = tmp_path / "show" / "x.png"
    assert main(["sim", "show", "--task", "stack_bowls", "--out", str(out), "--seed", "3"]) == 0
    assert str(out) in capsys.readouterr().out
    image = cv2.cvtColor(cv2.imread(str(out)), cv2.COLOR_BGR2RGB)
    scale = 2  # the default
    assert image.shape == (128 * scale, 3 * 128 * scale, 3)
    with SimRobot(SIM, "stack_bowls") as robot:
        start = robot.reset(seed=3, subtask=0, history=0)
    row = np.concatenate([start.observation.images[v] for v in robot.spec.cameras], axis=1)
    np.testing.assert_array_equal(image[::scale, ::scale], row)  # lossless, nearest-neighbour upscaled


def test_sim_collect_with_an_unknown_task_exits_2(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    code = main(["sim", "collect", "--task", "juggling", "--episodes", "1", "--out", str(tmp_path / "d")])
    assert code == 2
    err = capsys.readouterr().err
    assert "--task" in err and "juggling" in err
    for name in TASK_NAMES:
        assert name in err
    assert not (tmp_path / "d").exists()


def test_sim_collect_with_no_episodes_exits_2(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["sim", "collect", "--episodes", "0", "--out", str(tmp_path / "d")]) == 2
    assert "--episodes: expected an integer in 1..100,000" in capsys.readouterr().err


def test_bench_sim_prints_speed_figures_as_json(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["bench", "sim", "--task", TASK, "--json"]) == 0
    result = json.loads(capsys.readouterr().out.strip().splitlines()[-1])
    for key in ("physics_steps_per_s", "render_ms_per_view", "realtime_factor"):
        assert isinstance(result[key], float) and result[key] > 0, key
    assert result["task"] == TASK and result["image_size"] == [128, 128]
    assert "success_rates" not in result


def test_bench_sim_times_a_baseline_look_side_by_side(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["bench", "sim", "--task", TASK, "--appearance", "varied", "--baseline", "flat", "--json"]) == 0
    out = capsys.readouterr().out.strip().splitlines()
    result = json.loads(out[-1])
    assert result["appearance"] == "varied" and result["repeats"] == 1
    assert result["baseline"]["appearance"] == "flat"
    for key in ("render_ms_per_view", "realtime_factor"):
        ratio = result[key] / result["baseline"][key]
        assert result["baseline_ratio"][key] == pytest.approx(ratio, rel=0.01), key
    assert any("varied / flat" in line for line in out)


def test_bench_sim_refuses_a_repeat_count_out_of_bounds(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["bench", "sim", "--repeats", "0"]) == 2
    assert "--repeats: expected an integer in 1..50" in capsys.readouterr().err


def test_bench_sim_success_rates_shape(capsys: pytest.CaptureFixture[str]) -> None:
    args = ["bench", "sim", "--task", TASK, "--subtasks", "1", "--tasks", TASK]
    assert main([*args, "--checkpoints", BEST_CHECKPOINT, "--workers", "1", "--json"]) == 0
    result = json.loads(capsys.readouterr().out.strip().splitlines()[-1])
    rates = result["success_rates"]
    assert set(rates) == {TASK} and set(rates[TASK]) == {BEST_CHECKPOINT}
    assert rates[TASK][BEST_CHECKPOINT] in (0.0, 1.0)  # one subtask start
    assert result["subtasks"] == 1
    assert set(result["mean_by_checkpoint"]) == {BEST_CHECKPOINT}
    assert isinstance(result["spread_ok"], bool)


def test_bench_sim_with_an_unknown_checkpoint_exits_2(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["bench", "sim", "--subtasks", "1", "--checkpoints", "step_99k"]) == 2
    err = capsys.readouterr().err
    assert "--checkpoints" in err and all(c.name in err for c in CHECKPOINTS)
