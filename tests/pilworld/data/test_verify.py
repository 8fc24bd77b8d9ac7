"""``pilworld data verify`` and ``data info``'s cheap check find any one damaged file of a finished paired run.

Every file kind a run stores — an episode's data parquet and mp4, the episodes table, the starts/ dataset's
files, the outcomes table, info.json — is deleted, cut short or has one byte flipped. Deleting and cutting
short change a size (found by the cheap check too); a flipped byte keeps the size and only the sha256 in the
episode's manifest finds it.
"""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import pytest

from pilworld.cli.main import main
from pilworld.paired import PairedConfig, paired_run
from pilworld.types import ChunkSpec
from tests.pilworld.data.damage import damage

SIM = "configs/rig/sim_dual_ur5e.yaml"
FILES = {
    "data parquet": "data/chunk-000/file-000.parquet",
    "video": "videos/observation.images.cam_high/chunk-000/file-000.mp4",
    "episodes table": "meta/episodes/chunk-000/file-000.parquet",
    "starts video": "starts/videos/observation.images.cam_high/chunk-000/file-000.mp4",
    "starts data": "starts/data/chunk-000/file-000.parquet",
    "outcomes": "meta/outcomes.parquet",
    "info.json": "meta/info.json",
    "tasks": "meta/tasks.parquet",
    "spec": "meta/pilworld.json",
    "manifest": "meta/manifest.json",
    "outcomes manifest": "meta/outcomes_manifest.json",
    "settings": "paired_config.json",
    "timings": "paired_timings.jsonl",
    "episodes table backup": "meta/backup/meta/episodes/chunk-000/file-000.parquet",
    "info.json backup": "meta/backup/meta/info.json",
    "manifest backup": "meta/backup/meta/manifest.json",
    "settings backup": "meta/backup/paired_config.json",
}


@pytest.fixture(scope="module")
def finished_run(tmp_path_factory: pytest.TempPathFactory) -> Path:
    out = tmp_path_factory.mktemp("verify") / "run"
    cfg = PairedConfig(
        rig=SIM,
        task="sort_cubes",
        checkpoints=["scripted_step_30k"],
        subtasks=1,
        out=str(out),
        spec=ChunkSpec(rounds=1),
    )
    paired_run(cfg, progress=False)
    return out


def _verify(path: Path, capsys: pytest.CaptureFixture[str], *extra: str) -> tuple[int, dict[str, object]]:
    capsys.readouterr()
    rc = main(["data", "verify", str(path), "--json", "--no-progress", *extra])
    return rc, json.loads(capsys.readouterr().out.strip().splitlines()[-1])


def test_a_finished_run_verifies(finished_run: Path, capsys: pytest.CaptureFixture[str]) -> None:
    for name, rel in FILES.items():
        assert (finished_run / rel).is_file(), f"the run has no {name} at {rel}: FILES is out of date"
    rc, report = _verify(finished_run, capsys)
    assert rc == 0, report


@pytest.mark.parametrize("how", ["delete", "truncate", "corrupt"])
@pytest.mark.parametrize("kind", list(FILES))
def test_any_one_damaged_file_is_found(
    finished_run: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str], kind: str, how: str
) -> None:
    run = tmp_path / "run"
    shutil.copytree(finished_run, run)
    damage(run / FILES[kind], how)
    rc, report = _verify(run, capsys)
    assert rc == 1, f"{kind} {how}: not detected: {report}"
    assert FILES[kind].split("/")[-1] in json.dumps(report), report
    if how != "corrupt":  # a size changed: the cheap checks see it too
        assert _verify(run, capsys, "--sizes-only")[0] == 1
        capsys.readouterr()
        if not kind.startswith("starts"):
            # data info: exit 1 either way: DAMAGED, or a table it cannot read named in its one-line error
            rc = main(["data", "info", str(run)])
            out = capsys.readouterr()
            assert rc == 1 and ("DAMAGED" in out.out or FILES[kind] in out.err), (rc, out)


def test_not_a_dataset_is_bad_input(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["data", "verify", str(tmp_path)]) == 2
    assert main(["data", "verify", str(tmp_path / "missing")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert err and all(line.startswith("pilworld: error:") for line in err), err
