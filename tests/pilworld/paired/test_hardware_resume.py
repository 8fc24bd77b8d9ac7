"""On a rig whose scenes are set up by hand, a resumed pair keeps both branches on one start.

A set-up scene cannot be repeated, so the paired run on the fake rig (``--unattended``) must (1) store
the start only after the real branch ran from it — writing the start first would age the observation
behind the first chunk past the safety filter's limit on a busy machine — (2) imagine a pair whose real
branch is stored from the stored start, without moving the robot, and (3) run both branches again from
a new scene when the real branch is lost, rewriting the start and the imagined branch in their slots.
"""

from __future__ import annotations

import shutil
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from pilworld.data.reader import EpisodeStore
from pilworld.data.verify import check_dataset
from pilworld.paired import PairedConfig, paired_run
from pilworld.paired.operator import UnattendedOperator
from pilworld.paired.stations import HardwareStation
from pilworld.starts.sources import PAIRED_STARTS
from pilworld.types import ChunkSpec

FAKE = "configs/rig/fake_dual_ur5e.yaml"


class _InterruptedError(Exception):
    pass


def _cfg(out: Path) -> PairedConfig:
    return PairedConfig(
        rig=FAKE,
        task="sort_cubes",
        checkpoints=["scripted_step_30k"],
        subtasks=1,
        out=str(out),
        spec=ChunkSpec(rounds=1),
    )


def _branches(run: Path) -> dict[str, int]:
    return {str(row["origin"]): i for i, row in enumerate(EpisodeStore(run).episodes)}


def _start_frame(run: Path) -> np.ndarray[Any, Any]:
    starts = EpisodeStore(run / PAIRED_STARTS)
    assert starts.num_episodes == 1, "one pair: one stored start"
    ep = starts.load(0)
    return np.asarray(ep.images["cam_high"][-1])


def _first_frame(run: Path, origin: str) -> np.ndarray[Any, Any]:
    ep = EpisodeStore(run).load(_branches(run)[origin])
    return np.asarray(ep.images["cam_high"][0])


@pytest.fixture(scope="module")
def real_only(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A fake-rig run interrupted right after its real branch was stored."""
    out = tmp_path_factory.mktemp("hw_resume") / "run"

    def stop_after(pair: Any, origin: str) -> None:
        if origin == "real":
            raise _InterruptedError

    with pytest.raises(_InterruptedError):
        paired_run(_cfg(out), progress=False, on_branch=stop_after, operator=UnattendedOperator())
    assert set(_branches(out)) == {"real"}
    return out


def test_the_real_branch_runs_first_and_its_start_is_stored_with_it(real_only: Path) -> None:
    np.testing.assert_array_equal(_first_frame(real_only, "real"), _start_frame(real_only))


def test_a_stored_real_branch_is_imagined_from_its_own_start(
    real_only: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    run = tmp_path / "run"
    shutil.copytree(real_only, run)
    start_before = _start_frame(run)

    def no_new_scene(*a: object, **k: object) -> None:
        raise AssertionError("the robot set a new scene up for a pair whose real branch is stored")

    monkeypatch.setattr(HardwareStation, "start", no_new_scene)
    summary = paired_run(_cfg(run), progress=False, operator=UnattendedOperator())
    assert summary["branches_run"] == 1
    assert set(_branches(run)) == {"real", "imagined"}
    np.testing.assert_array_equal(_start_frame(run), start_before)
    np.testing.assert_array_equal(_first_frame(run, "imagined"), start_before)
    assert not check_dataset(run, hash_files=True).problems


def test_a_lost_real_branch_runs_the_pair_again_from_a_new_scene(
    real_only: Path, tmp_path: Path, capfd: pytest.CaptureFixture[str]
) -> None:
    run = tmp_path / "run"
    shutil.copytree(real_only, run)
    paired_run(_cfg(run), progress=False, operator=UnattendedOperator())  # finish the pair
    slots = _branches(run)
    # The real branch's data is lost: its imagined partner ran from a scene no one can set up again.
    store = EpisodeStore(run)
    row = store.episodes[slots["real"]]
    (
        run / store.data_path.format(chunk_index=int(row["data/chunk_index"]), file_index=int(row["data/file_index"]))
    ).unlink()
    capfd.readouterr()
    summary = paired_run(_cfg(run), progress=False, operator=UnattendedOperator())
    err = capfd.readouterr().err
    assert "both branches run again from a new one" in err, err
    assert summary["branches_run"] == 2
    assert _branches(run) == slots, "both branches rewritten in their own slots"
    start = _start_frame(run)
    np.testing.assert_array_equal(_first_frame(run, "real"), start)
    np.testing.assert_array_equal(_first_frame(run, "imagined"), start)
    assert not check_dataset(run, hash_files=True).problems
