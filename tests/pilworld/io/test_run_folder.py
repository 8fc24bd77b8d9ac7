"""What made a run folder (pilworld.io.run_folder): markers, their backups, and refusals."""

from __future__ import annotations

from pathlib import Path

import pytest

from pilworld.io.run_folder import EPISODE_STORE, IMAGINED, PAIRED, STARTS, check_out_folder, kind_of


def _store(root: Path) -> None:
    (root / "meta").mkdir(parents=True)
    (root / "meta" / "info.json").write_text("{}")


@pytest.mark.parametrize(("marker", "kind"), [("paired_config.json", PAIRED), ("imagine_config.json", IMAGINED)])
def test_a_marker_names_its_kind_and_its_backup_stands_in_when_it_is_deleted(
    tmp_path: Path, marker: str, kind: str
) -> None:
    run = tmp_path / "run"
    _store(run)
    assert kind_of(run) == EPISODE_STORE
    (run / marker).write_text("{}")
    assert kind_of(run) == kind
    backup = run / "meta" / "backup" / marker
    backup.parent.mkdir(parents=True)
    backup.write_text("{}")
    (run / marker).unlink()  # the resume puts it back from the backup; the folder is still the run's own
    assert kind_of(run) == kind
    assert check_out_folder(run, kind) == kind
    with pytest.raises(ValueError, match=f"holds an? {kind}"):
        check_out_folder(run, STARTS)


def test_absent_empty_and_a_killed_writers_meta_are_nothing_yet(tmp_path: Path) -> None:
    assert kind_of(tmp_path / "absent") is None
    assert kind_of(tmp_path) is None
    (tmp_path / "meta").mkdir()
    assert kind_of(tmp_path) is None
    (tmp_path / "notes.txt").write_text("x")
    assert kind_of(tmp_path) == "other"
    assert kind_of(tmp_path / "notes.txt") == "file"
