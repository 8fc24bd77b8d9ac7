"""Real branches copied from another paired run (``PairedConfig.real_from``), the no-history ablation at
inference (``history=False``), and resuming a run whose ``paired_config.json`` predates the new keys.
"""

from __future__ import annotations

import json
import shutil
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from pilworld.config.rig import RigConfig
from pilworld.data.episode import Episode
from pilworld.data.outcomes import Outcome, read_outcomes, record_outcomes
from pilworld.data.pairs import load_pairs
from pilworld.data.reader import EpisodeStore
from pilworld.paired import PairedConfig, paired_run
from pilworld.paired.runner import CONFIG_FILE, TIMINGS_FILE, load_model
from pilworld.types import ChunkSpec
from pilworld.world_model import V1_CHECKPOINT
from pilworld.world_model.latent.model import HistoryAblated, PilWorldModel

SIM = "configs/rig/sim_dual_ur5e.yaml"
ONE = ChunkSpec(rounds=1)
EARLY, LATE = "scripted_step_01k", "scripted_step_30k"


def _cfg(out: Path, **kw: object) -> PairedConfig:
    args: dict[str, object] = {
        "rig": SIM,
        "task": "sort_cubes",
        "checkpoints": [LATE],
        "subtasks": 1,
        "out": str(out),
        "spec": ONE,
        "world_model": str(V1_CHECKPOINT),  # the history ablation and the task adapters are v1's
    }
    args.update(kw)
    return PairedConfig(**args)  # type: ignore[arg-type]


def _verdict_key(o: Outcome) -> tuple[object, ...]:
    return (o.judge_id, o.judge_kind, o.success, o.num_frames, o.first_hallucination_frame)


def _timing_origins(root: Path) -> list[str]:
    return [json.loads(line)["origin"] for line in (root / TIMINGS_FILE).read_text().splitlines()]


@pytest.fixture(scope="module")
def source(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """Run A: two checkpoints (episodes im, real, im, real) plus a person's verdicts on both real branches."""
    out = tmp_path_factory.mktemp("real_source") / "A"
    paired_run(_cfg(out, checkpoints=[EARLY, LATE]), progress=False)
    store = EpisodeStore(out)
    assert [store.load(i).origin for i in range(4)] == ["imagined", "real", "imagined", "real"]
    T = store.load(3).length
    # Different verdicts on the two real branches, so a copy under the wrong index shows.
    record_outcomes(out, [Outcome(1, "alice", "human", False, T), Outcome(3, "alice", "human", True, T, 2)])
    return out


@pytest.fixture(scope="module")
def copied(source: Path, tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, dict[str, Any]]:
    """Run B: only the late checkpoint, its real branch copied from A (A's episode 3 becomes B's episode 1)."""
    out = tmp_path_factory.mktemp("real_source") / "B"
    summary = paired_run(_cfg(out, real_from=str(source)), progress=False)
    return out, summary


def test_copied_real_branch_equals_the_source_episode(source: Path, copied: tuple[Path, dict[str, Any]]) -> None:
    """Frames, state, action, rounds and labels of the copied real episode are A's, byte for byte."""
    out, _ = copied
    a, b = EpisodeStore(source), EpisodeStore(out)
    assert b.num_episodes == 2
    src, real = a.load(3), b.load(1)
    assert b.load(0).origin == "imagined" and real.origin == "real"
    assert set(real.images) == set(src.images)
    for v in src.images:
        assert real.images[v].shape == src.images[v].shape
        assert real.images[v].tobytes() == src.images[v].tobytes(), v
        # Same dataset spec, so the mp4 itself was copied rather than encoded again.
        assert b.video_file(1, v)[0].read_bytes() == a.video_file(3, v)[0].read_bytes(), v
    np.testing.assert_array_equal(real.state, src.state)
    np.testing.assert_array_equal(real.action, src.action)
    np.testing.assert_array_equal(real.rounds(), src.rounds())
    assert (real.checkpoint, real.seed, real.subtask_index, real.task) == (
        src.checkpoint,
        src.seed,
        src.subtask_index,
        src.task,
    )
    assert real.extra == {**src.extra, "real_from": str(source), "real_from_index": 3}
    assert real.extra["pair"] == b.load(0).extra["pair"] == f"sort_cubes/{LATE}/seed0/subtask0"


def test_every_verdict_is_copied_under_the_new_index(source: Path, copied: tuple[Path, dict[str, Any]]) -> None:
    """The checker's and the person's verdicts on A's episode 3 land on B's episode 1 (and nothing else)."""
    out, _ = copied
    want = sorted(_verdict_key(o) for o in read_outcomes(source) if o.episode_index == 3)
    assert {o.judge_id for o in read_outcomes(source) if o.episode_index == 3} == {"sim_checker", "alice"}
    got = read_outcomes(out)
    assert {o.episode_index for o in got} == {1}
    assert sorted(_verdict_key(o) for o in got) == want
    alice = next(o for o in got if o.judge_id == "alice")
    assert alice.success is True and alice.first_hallucination_frame == 2  # A's episode 3, not episode 1
    paired = load_pairs(out)
    assert [(p.imagined, p.real) for p in paired.pairs] == [(0, 1)] and not paired.incomplete


def test_the_real_branch_is_not_rerun(source: Path, copied: tuple[Path, dict[str, Any]]) -> None:
    """Only the imagined branch ran in B: one timing record, one branch in the summary."""
    out, summary = copied
    assert _timing_origins(out) == ["imagined"]
    assert summary["branches_run"] == 1
    assert set(summary["seconds_per_subtask"]) == {"imagined"}
    # The imagined branch with the same model and seed is A's imagined branch of that pair.
    a_im, b_im = EpisodeStore(source).load(2), EpisodeStore(out).load(0)
    for v in a_im.images:
        assert a_im.images[v].tobytes() == b_im.images[v].tobytes(), v
    np.testing.assert_array_equal(a_im.action, b_im.action)
    # Resuming B copies and runs nothing more.
    assert paired_run(_cfg(out, real_from=str(source)), progress=False)["branches_run"] == 0
    assert EpisodeStore(out).num_episodes == 2


def test_a_damaged_copied_real_branch_is_copied_again(
    source: Path, copied: tuple[Path, dict[str, Any]], tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """A resume with real_from redoes a damaged real branch by copying it again, verdicts included."""
    out, _ = copied
    run = tmp_path / "B"
    shutil.copytree(out, run)
    mp4 = EpisodeStore(run).video_file(1, "cam_high")[0]
    mp4.unlink()
    capsys.readouterr()
    paired_run(_cfg(run, real_from=str(source)), progress=False)
    err = capsys.readouterr().err
    assert f"episode 1 (sort_cubes/{LATE}/seed0/subtask0, real): " in err and "missing — redoing" in err, err
    assert mp4.read_bytes() == EpisodeStore(out).video_file(1, "cam_high")[0].read_bytes()
    want = sorted((o.episode_index, *_verdict_key(o)) for o in read_outcomes(out))
    assert sorted((o.episode_index, *_verdict_key(o)) for o in read_outcomes(run)) == want


def test_real_from_without_a_paired_run_is_refused(tmp_path: Path) -> None:
    empty = tmp_path / "empty"
    empty.mkdir()
    with pytest.raises(FileNotFoundError, match=CONFIG_FILE):
        paired_run(_cfg(tmp_path / "out", real_from=str(empty)), progress=False)
    assert not (tmp_path / "out" / "meta").exists()


def test_real_from_with_other_settings_is_refused(source: Path, tmp_path: Path) -> None:
    """Another seed or chunk spec gives other real branches: refused, naming the setting."""
    with pytest.raises(ValueError, match=r"other settings \(seed\)"):
        paired_run(_cfg(tmp_path / "seed", real_from=str(source), seed=1), progress=False)
    with pytest.raises(ValueError, match=r"other settings \(spec\)"):
        paired_run(_cfg(tmp_path / "spec", real_from=str(source), spec=ChunkSpec(rounds=2)), progress=False)
    for name in ("seed", "spec"):
        assert not (tmp_path / name / "meta").exists()


def test_real_from_lacking_a_pair_fails_before_any_episode(source: Path, tmp_path: Path) -> None:
    """A has subtask 0 only; B wants subtasks 0 and 1: refused before any branch runs or is stored."""
    out = tmp_path / "more"
    with pytest.raises(ValueError, match=r"lacks the real branch of 1 pair\(s\), e\.g\. sort_cubes/.*/subtask1"):
        paired_run(_cfg(out, real_from=str(source), subtasks=2), progress=False)
    assert not (out / "meta").exists()
    assert not (out / TIMINGS_FILE).exists()


def test_history_false_runs_the_ablation(source: Path, tmp_path: Path) -> None:
    """history=False: the loaded model hides its memory, and the imagined branch differs from A's."""
    cfg = _cfg(tmp_path / "nohist", real_from=str(source), history=False)
    model, adapter = load_model(cfg, RigConfig.load(SIM), "sort_cubes")
    assert isinstance(model, HistoryAblated) and adapter == "sort_cubes"
    plain, _ = load_model(_cfg(tmp_path / "x"), RigConfig.load(SIM), "sort_cubes")
    assert isinstance(plain, PilWorldModel)

    paired_run(cfg, progress=False)
    a_im: Episode = EpisodeStore(source).load(2)
    store = EpisodeStore(cfg.out)
    b_im, b_real = store.load(0), store.load(1)
    assert b_real.extra["real_from"] == str(source)
    for v in a_im.images:
        assert a_im.images[v][0].tobytes() == b_im.images[v][0].tobytes(), v  # same start
    # The first policy chunk is the same (same start, policy and seed); the predicted frames are not.
    assert a_im.extra["chunk0"] == b_im.extra["chunk0"]
    assert any(not np.array_equal(a_im.images[v][1:], b_im.images[v][1:]) for v in a_im.images)


def test_an_older_config_without_the_new_keys_resumes(source: Path, tmp_path: Path) -> None:
    """A paired_config.json written before history/resize/real_from existed resumes with the defaults."""
    run = tmp_path / "old"
    shutil.copytree(source, run)
    path = run / CONFIG_FILE
    old = json.loads(path.read_text())
    for key in ("history", "resize", "real_from"):
        old.pop(key)
    path.write_text(json.dumps(old))

    cfg = _cfg(run, checkpoints=[EARLY, LATE])
    assert paired_run(cfg, progress=False)["branches_run"] == 0
    rewritten = json.loads(path.read_text())
    assert (rewritten["history"], rewritten["resize"], rewritten["real_from"]) == (True, False, "")
    # A missing key means the old behaviour, so a run asking for something else is still refused.
    path.write_text(json.dumps(old))
    with pytest.raises(ValueError, match=r"different settings \(history\)"):
        paired_run(_cfg(run, checkpoints=[EARLY, LATE], history=False), progress=False)


def test_resume_ignores_real_from(source: Path, copied: tuple[Path, dict[str, Any]], tmp_path: Path) -> None:
    """A copied real branch equals a re-run one, so real_from may change on resume; other settings may not."""
    run = tmp_path / "B"
    shutil.copytree(copied[0], run)
    assert paired_run(_cfg(run), progress=False)["branches_run"] == 0  # real_from dropped
    with pytest.raises(ValueError, match=r"different settings \(resize\)"):
        paired_run(_cfg(run, real_from=str(source), resize=True), progress=False)


def test_a_refused_real_from_leaves_the_out_folder_unclaimed(source: Path, tmp_path: Path) -> None:
    """After real_from is refused for a wrong seed, the corrected command works in the same --out folder."""
    out = tmp_path / "retry"
    with pytest.raises(ValueError, match="seed"):
        paired_run(_cfg(out, real_from=str(source), seed=1), progress=False)
    assert not (out / CONFIG_FILE).exists()
    with pytest.raises(ValueError, match="lacks the real branch"):
        paired_run(_cfg(out, real_from=str(source), subtasks=2), progress=False)
    assert not (out / CONFIG_FILE).exists()
