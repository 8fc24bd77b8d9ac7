"""A resumed paired run redoes the branches whose files were lost, and ends with the run an undamaged one is.

A finished tiny run is copied, one branch's data parquet or mp4 is deleted or cut short, and the same
command runs again: it names each damaged episode on stderr in one line, runs that branch again into its
old slot, and afterwards ``pilworld data verify`` passes and every episode's frames and every verdict
equal the undamaged run's.
"""

from __future__ import annotations

import shutil
from pathlib import Path

import pytest

from pilworld.cli.main import main
from pilworld.data.outcomes import read_outcomes
from pilworld.data.reader import DatasetError, EpisodeStore
from pilworld.paired import PairedConfig, paired_run
from pilworld.types import ChunkSpec
from tests.pilworld.data.damage import damage
from tests.pilworld.paired.digest import dataset_digest

SIM = "configs/rig/sim_dual_ur5e.yaml"
VIDEO = "videos/observation.images.cam_high"


def _cfg(out: Path) -> PairedConfig:
    return PairedConfig(
        rig=SIM,
        task="sort_cubes",
        checkpoints=["scripted_step_30k"],
        subtasks=1,
        out=str(out),
        spec=ChunkSpec(rounds=1),
    )


@pytest.fixture(scope="module")
def finished_run(tmp_path_factory: pytest.TempPathFactory) -> Path:
    out = tmp_path_factory.mktemp("integrity") / "run"
    paired_run(_cfg(out), progress=False)
    return out


def _file_of(run: Path, origin: str, kind: str) -> tuple[int, str]:
    """(episode index, its data parquet or cam_high mp4 relative to the run) of the branch of ``origin``."""
    store = EpisodeStore(run)
    index = next(i for i, row in enumerate(store.episodes) if row["origin"] == origin)
    row = store.episodes[index]
    if kind == "data":
        c, f = int(row["data/chunk_index"]), int(row["data/file_index"])
        return index, store.data_path.format(chunk_index=c, file_index=f)
    key = "observation.images.cam_high"
    c, f = int(row[f"videos/{key}/chunk_index"]), int(row[f"videos/{key}/file_index"])
    return index, store.video_path.format(video_key=key, chunk_index=c, file_index=f)


@pytest.mark.parametrize(
    ("origin", "kind", "how"),
    [
        ("real", "data", "delete"),
        ("imagined", "video", "truncate"),
        ("real", "video", "truncate"),
        ("real", "data", "corrupt"),
        ("imagined", "video", "corrupt"),
    ],
)
def test_a_resume_redoes_a_damaged_branch(
    finished_run: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str], origin: str, kind: str, how: str
) -> None:
    run = tmp_path / "run"
    shutil.copytree(finished_run, run)
    index, rel = _file_of(run, origin, kind)
    path = run / rel
    damage(path, how)
    capsys.readouterr()
    assert main(["data", "verify", str(run), "--no-progress"]) == 1  # the damage is real
    capsys.readouterr()

    summary = paired_run(_cfg(run), progress=False)

    err = capsys.readouterr().err
    lines = [line for line in err.splitlines() if line.endswith("— redoing")]
    pair = "sort_cubes/scripted_step_30k/seed0/subtask0"
    # a cut-short file: "is N bytes, manifest says M"; a flipped byte: "content differs from its sha256 …"
    detail = {"delete": "missing", "truncate": "is", "corrupt": "content differs"}[how]
    assert lines and lines[0].startswith(f"episode {index} ({pair}, {origin}): {rel} {detail}"), err
    assert len(lines) == 1, err
    assert summary["branches_run"] == 1  # only the damaged branch ran again
    assert main(["data", "verify", str(run), "--no-progress"]) == 0, capsys.readouterr().out
    assert dataset_digest(run) == dataset_digest(finished_run)
    verdicts = sorted((o.episode_index, o.judge_id) for o in read_outcomes(run))
    assert verdicts == sorted((o.episode_index, o.judge_id) for o in read_outcomes(finished_run))
    assert len(verdicts) == len(set(verdicts))  # a redone real branch's verdict is recorded once

    capsys.readouterr()
    paired_run(_cfg(run), progress=False)  # a second resume finds nothing to redo
    assert "redoing" not in capsys.readouterr().err


@pytest.mark.parametrize("rel", ["starts/data/chunk-000/file-000.parquet", f"starts/{VIDEO}/chunk-000/file-000.mp4"])
def test_a_resume_records_a_damaged_start_again(
    finished_run: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str], rel: str
) -> None:
    run = tmp_path / "run"
    shutil.copytree(finished_run, run)
    (run / rel).unlink()
    capsys.readouterr()
    summary = paired_run(_cfg(run), progress=False)
    lines = [line for line in capsys.readouterr().err.splitlines() if line.endswith("— redoing")]
    short = rel.removeprefix("starts/")
    assert lines == [f"starts episode 0 (sort_cubes/seed0/subtask0): {short} missing — redoing"], lines
    assert summary["branches_run"] == 0  # both branches were whole: only the start is recorded again
    assert main(["data", "verify", str(run), "--no-progress"]) == 0, capsys.readouterr().out
    assert dataset_digest(run / "starts") == dataset_digest(finished_run / "starts")
    assert dataset_digest(run) == dataset_digest(finished_run)


# Every table and setting a run keeps (its own dataset's, its starts/'s), and one backup copy.
TABLES = [
    "meta/episodes/chunk-000/file-000.parquet",
    "meta/info.json",
    "meta/tasks.parquet",
    "meta/stats.json",
    "meta/pilworld.json",
    "meta/manifest.json",
    "meta/outcomes.parquet",
    "meta/outcomes_manifest.json",
    "paired_config.json",
    "paired_timings.jsonl",
    "starts/meta/episodes/chunk-000/file-000.parquet",
    "starts/starts.json",
    "meta/backup/meta/episodes/chunk-000/file-000.parquet",
]


def _check_restored(run: Path, finished_run: Path, rel: str, capsys: pytest.CaptureFixture[str]) -> None:
    capsys.readouterr()
    assert main(["data", "verify", str(run), "--no-progress"]) == 1, f"{rel}: the damage is not real"
    capsys.readouterr()
    summary = paired_run(_cfg(run), progress=False)
    err = capsys.readouterr().err
    assert summary["branches_run"] == 0, f"{rel}: a table's damage made branches run again:\n{err}"
    if not rel.startswith("meta/backup/"):  # a damaged backup is copied again quietly; a table is announced
        assert "restored from meta/backup/" in err and rel.split("/")[-1] in err, err
    assert main(["data", "verify", str(run), "--no-progress"]) == 0, capsys.readouterr().out
    for name in ("meta/info.json", "paired_config.json", "starts/starts.json", "paired_timings.jsonl"):
        assert (run / name).read_bytes() == (finished_run / name).read_bytes(), name
    assert dataset_digest(run) == dataset_digest(finished_run)
    assert dataset_digest(run / "starts") == dataset_digest(finished_run / "starts")
    verdicts = sorted((o.episode_index, o.judge_id, o.success) for o in read_outcomes(run))
    assert verdicts == sorted((o.episode_index, o.judge_id, o.success) for o in read_outcomes(finished_run))


@pytest.mark.parametrize("rel", TABLES)
def test_a_resume_restores_a_corrupted_table(
    finished_run: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str], rel: str
) -> None:
    run = tmp_path / "run"
    shutil.copytree(finished_run, run)
    damage(run / rel, "corrupt")
    _check_restored(run, finished_run, rel, capsys)


@pytest.mark.slow
@pytest.mark.parametrize("how", ["delete", "truncate"])
@pytest.mark.parametrize("rel", TABLES)
def test_a_resume_restores_a_deleted_or_cut_short_table(
    finished_run: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str], rel: str, how: str
) -> None:
    run = tmp_path / "run"
    shutil.copytree(finished_run, run)
    damage(run / rel, how)
    _check_restored(run, finished_run, rel, capsys)


def test_a_table_and_its_backup_both_damaged_are_refused_by_name(finished_run: Path, tmp_path: Path) -> None:
    run = tmp_path / "run"
    shutil.copytree(finished_run, run)
    for rel in ("meta/episodes/chunk-000/file-000.parquet", "meta/backup/meta/episodes/chunk-000/file-000.parquet"):
        table = run / rel
        table.write_bytes(table.read_bytes()[:100])
    with pytest.raises(DatasetError, match=r"meta/episodes/chunk-000/file-000\.parquet .*and its backup"):
        paired_run(_cfg(run), progress=False)


def test_the_cli_resume_redoes_a_damaged_branch(
    finished_run: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    run = tmp_path / "run"
    shutil.copytree(finished_run, run)
    index, rel = _file_of(run, "real", "data")
    (run / rel).unlink()
    capsys.readouterr()
    args = ["paired", "run", "--rig", SIM, "--task", "sort_cubes", "--checkpoints", "scripted_step_30k"]
    assert main([*args, "--subtasks", "1", "--rounds", "1", "--out", str(run), "--json"]) == 0
    err = capsys.readouterr().err
    assert f"episode {index} (sort_cubes/scripted_step_30k/seed0/subtask0, real): {rel} missing — redoing" in err
    assert main(["data", "verify", str(run), "--no-progress"]) == 0
    assert dataset_digest(run) == dataset_digest(finished_run)
