"""pilworld imagine: byte-for-byte the paired run's imagined branches, resumable after SIGKILL, clear errors."""

from __future__ import annotations

import hashlib
import json
import os
import shutil
import signal
import socket
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from pilworld.cli.main import main
from pilworld.data.reader import EpisodeStore
from pilworld.imagine.runner import ImagineConfig, imagine_run
from pilworld.paired import PairedConfig, paired_run
from pilworld.starts import StartsError, load_starts
from pilworld.types import ChunkSpec
from simrig.files import SIM_RIG

CKPTS = ["scripted_step_30k", "scripted_step_05k"]
SPEC = ChunkSpec(rounds=2)


@pytest.fixture(scope="module")
def paired(tmp_path_factory: pytest.TempPathFactory) -> Path:
    os.environ.setdefault("MUJOCO_GL", "egl")
    out = tmp_path_factory.mktemp("imagine") / "paired"
    cfg = PairedConfig(
        rig=str(SIM_RIG), task="sort_cubes", checkpoints=CKPTS, subtasks=2, out=str(out), seed=7_300_000, spec=SPEC
    )
    paired_run(cfg, progress=False)
    return out


def _by_pair(root: Path, origin: str = "imagined") -> dict[str, int]:
    store = EpisodeStore(root)
    return {json.loads(r["extra"])["pair"]: i for i, r in enumerate(store.episodes) if str(r["origin"]) == origin}


def _digest(root: Path) -> list[Any]:
    store = EpisodeStore(root)
    out = []
    for i in range(store.num_episodes):
        ep = store.load(i)
        out.append(
            (
                ep.extra["pair"],
                ep.checkpoint,
                ep.seed,
                hashlib.sha256(ep.state.tobytes() + ep.action.tobytes()).hexdigest(),
                {v: hashlib.sha256(f.tobytes()).hexdigest() for v, f in sorted(ep.images.items())},
            )
        )
    return out


def _videos(root: Path) -> list[str]:
    return [hashlib.sha256(p.read_bytes()).hexdigest() for p in sorted((root / "videos").rglob("*.mp4"))]


@pytest.fixture(scope="module")
def imagined(paired: Path) -> Path:
    import torch

    out = paired.parent / "imagined"
    before = torch.get_num_threads()
    # Another thread count in this process than in the paired run and the workers below (earlier tests
    # leave it changed, too): the imagined branch runs at its own fixed count, so nothing changes.
    torch.set_num_threads(1 if before != 1 else 2)
    try:
        imagine_run(ImagineConfig(starts=str(paired), checkpoints=CKPTS, out=str(out)), progress=False)
    finally:
        torch.set_num_threads(before)
    return out


def test_a_paired_run_keeps_its_starts_once_per_scene(paired: Path) -> None:
    source = load_starts(paired, history=SPEC.history)
    assert source.kind == "paired"
    assert [s.start_id for s in source.starts] == ["sort_cubes/seed7300000/subtask0", "sort_cubes/seed7300000/subtask1"]
    assert all(len(s.start.history) == SPEC.history and s.checkpoint == "" for s in source.starts)


def test_imagine_reproduces_the_paired_runs_imagined_branches_byte_for_byte(paired: Path, imagined: Path) -> None:
    a, b = EpisodeStore(paired), EpisodeStore(imagined)
    want, got = _by_pair(paired), _by_pair(imagined)
    assert set(want) == set(got) and len(got) == 4
    for pair, i in want.items():
        ea, eb = a.load(i), b.load(got[pair])
        for v in ea.images:
            assert np.array_equal(ea.images[v], eb.images[v]), (pair, v)
        assert np.array_equal(ea.state, eb.state) and np.array_equal(ea.action, eb.action)
        assert ea.extra["chunk0"] == eb.extra["chunk0"]
        for v in a.spec.views:  # the lossless mp4s themselves, byte for byte
            pa, pb = a.own_video_file(i, v), b.own_video_file(got[pair], v)
            assert pa is not None and pb is not None and pa.read_bytes() == pb.read_bytes()


def test_worker_processes_write_the_same_run(paired: Path, imagined: Path) -> None:
    out = paired.parent / "imagined_workers"
    imagine_run(ImagineConfig(starts=str(paired), checkpoints=CKPTS, out=str(out)), workers=2, progress=False)
    assert _digest(out) == _digest(imagined)
    assert _videos(out) == _videos(imagined)


def test_a_resume_redoes_a_damaged_branch(paired: Path, imagined: Path, capsys: pytest.CaptureFixture[str]) -> None:
    out = paired.parent / "damaged"
    shutil.copytree(imagined, out)
    store = EpisodeStore(out)
    row = store.episodes[1]
    rel = store.data_path.format(chunk_index=int(row["data/chunk_index"]), file_index=int(row["data/file_index"]))
    (out / rel).unlink()
    capsys.readouterr()
    summary = imagine_run(ImagineConfig(starts=str(paired), checkpoints=CKPTS, out=str(out)), progress=False)
    lines = [line for line in capsys.readouterr().err.splitlines() if line.endswith("— redoing")]
    pair = json.loads(str(row["extra"]))["pair"]
    assert lines == [f"episode 1 ({pair}, imagined): {rel} missing — redoing"], lines
    assert summary["branches_run"] == 1
    assert _digest(out) == _digest(imagined)
    assert _videos(out) == _videos(imagined)
    assert main(["data", "verify", str(out), "--no-progress"]) == 0


def _cmd(starts: Path, out: Path, *extra: str) -> list[str]:
    return [
        sys.executable, "-m", "pilworld.cli.main", "imagine", "--starts", str(starts), "--checkpoints", ",".join(CKPTS),
        "--out", str(out), "--no-judge", "--json", *extra,
    ]  # fmt: skip


def test_a_killed_run_resumes_to_identical_results(paired: Path, imagined: Path) -> None:
    env = {**os.environ, "MUJOCO_GL": os.environ.get("MUJOCO_GL", "egl")}
    out = paired.parent / "killed"
    proc = subprocess.Popen(_cmd(paired, out), env=env, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    timings = out / "imagine_timings.jsonl"
    deadline = time.monotonic() + 300
    while time.monotonic() < deadline and proc.poll() is None:
        if timings.is_file() and len(timings.read_text().splitlines()) >= 1:
            break
        time.sleep(0.02)
    assert proc.poll() is None, "the run finished before it could be killed"
    proc.send_signal(signal.SIGKILL)
    proc.wait(timeout=30)
    stored = EpisodeStore(out).num_episodes
    assert 1 <= stored < 4
    done = subprocess.run(_cmd(paired, out), check=True, env=env, capture_output=True, text=True, timeout=600)
    summary = json.loads(done.stdout.strip().splitlines()[-1])
    assert summary["branches_run"] == 4 - stored  # only what was missing ran
    assert _digest(out) == _digest(imagined)
    assert _videos(out) == _videos(imagined)


def test_the_learned_judge_judges_by_default_and_the_reference_only_on_request(imagined: Path, tmp_path: Path) -> None:
    """Nothing defaults to the paper tasks' hand-written judge: without --judge the shipped learned judge judges
    success (beside the task-free detector); ``--judge reference`` asks for the hand-written one."""
    from pilworld.data.outcomes import read_outcomes

    for extra, judge in (([], "learned"), (["--judge", "reference"], "vision")):
        out = tmp_path / judge
        shutil.copytree(imagined, out)
        args = ["imagine", "--starts", str(imagined.parent / "paired"), "--checkpoints", ",".join(CKPTS)]
        assert main([*args, "--out", str(out), "--judge-workers", "1", *extra]) == 0
        judged = {o.judge_id for o in read_outcomes(out)}
        assert judge in judged and judged <= {judge, "auto_hallucination"}, judged


def test_a_rerun_with_other_settings_is_refused(
    paired: Path, imagined: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    before = _digest(imagined)
    rc = main(["imagine", "--starts", str(paired), "--checkpoints", CKPTS[0], "--out", str(imagined), "--steps", "3"])
    assert rc == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "different settings" in err[0] and "steps" in err[0]
    assert _digest(imagined) == before


def _one_line_error(args: list[str], capsys: pytest.CaptureFixture[str], status: int = 2) -> str:
    assert main(args) == status
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("pilworld: error: "), err
    return err[0]


def test_no_starts_is_one_line(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    (tmp_path / "empty").mkdir()
    msg = _one_line_error(
        ["imagine", "--starts", str(tmp_path / "empty"), "--checkpoints", CKPTS[0], "--out", str(tmp_path / "o")],
        capsys,
    )
    assert "holds no starts" in msg
    msg = _one_line_error(
        ["imagine", "--starts", str(tmp_path / "nowhere"), "--checkpoints", CKPTS[0], "--out", str(tmp_path / "o")],
        capsys,
    )
    assert "does not exist" in msg
    assert not (tmp_path / "o").exists()


def test_a_start_without_history_is_one_line(paired: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    # A paired run's episodes read as a plain dataset: frame 0 has no frames before it.
    data = tmp_path / "dataset"
    shutil.copytree(paired, data, ignore=shutil.ignore_patterns("starts", "paired_config.json"))
    with pytest.raises(StartsError, match="no history frames"):
        load_starts(data, history=SPEC.history, start_frame=0)
    msg = _one_line_error(
        [
            "imagine",
            "--starts",
            str(data),
            "--start-frame",
            "0",
            "--checkpoints",
            CKPTS[0],
            "--out",
            str(tmp_path / "o"),
        ],
        capsys,
    )
    assert "no history frames" in msg and "dataset episode 1" in msg  # episode 0 is imagined: skipped


def test_a_later_frame_of_any_dataset_is_a_start(paired: Path, tmp_path: Path) -> None:
    data = tmp_path / "dataset"
    shutil.copytree(paired, data, ignore=shutil.ignore_patterns("starts", "paired_config.json"))
    source = load_starts(data, history=SPEC.history)
    assert source.kind == "dataset" and len(source.starts) == 4  # the real episodes only
    s = source.starts[0]
    ep = EpisodeStore(data).load(s.episode_index)
    assert np.array_equal(s.start.observation.images["cam_high"], ep.images["cam_high"][SPEC.history])
    assert len(s.start.history) == SPEC.history


def _free_port() -> int:
    with socket.socket() as sock:
        sock.bind(("127.0.0.1", 0))
        return int(sock.getsockname()[1])


def test_a_checkpoint_that_does_not_answer_is_one_line(
    paired: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    url = f"ws://127.0.0.1:{_free_port()}"
    out = tmp_path / "o"
    # a policy that fails is a run failure (exit 1, as in paired run); a name that is no checkpoint is bad input (2)
    msg = _one_line_error(["imagine", "--starts", str(paired), "--checkpoints", url, "--out", str(out)], capsys, 1)
    assert f"checkpoint {url} (connecting): unreachable" in msg, msg
    assert not out.exists()  # refused before anything was written
    msg = _one_line_error(["imagine", "--starts", str(paired), "--checkpoints", "nope", "--out", str(out)], capsys)
    assert "nope" in msg


def test_record_starts_equals_a_paired_runs_starts(paired: Path, tmp_path: Path) -> None:
    out = tmp_path / "starts"
    argv = ["paired", "record-starts", "--task", "sort_cubes", "--count", "2", "--seed", "7300000", "--rounds", "2"]
    assert main([*argv, "--out", str(out), "--json"]) == 0
    assert main([*argv, "--out", str(out), "--json"]) == 0  # resumes: nothing new
    assert EpisodeStore(out).num_episodes == 2
    a, b = load_starts(out, history=SPEC.history), load_starts(paired, history=SPEC.history)
    for sa, sb in zip(a.starts, b.starts, strict=True):
        assert sa.start_id == sb.start_id
        for oa, ob in zip(
            (*sa.start.history, sa.start.observation), (*sb.start.history, sb.start.observation), strict=True
        ):
            assert all(np.array_equal(oa.images[v], ob.images[v]) for v in oa.images)
            assert np.array_equal(oa.state, ob.state) and oa.timestamp == ob.timestamp
