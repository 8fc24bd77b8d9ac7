"""An openpi server's ``reset_pose`` metadata: read, checked, honoured on a hardware rig, refused on the simulator.

openpi's ALOHA examples put the pose a policy was trained to start from in the server's metadata. On a
hardware rig (here the fake rig, driven through the real client libraries) the arms go there instead of
the rig's start pose before the start is recorded; the simulated rig lays its starts out with the arms at
home, shared by both branches and every checkpoint, so it says in one line that the pose is not applied.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from pilworld.data.reader import EpisodeStore
from pilworld.paired import PairedConfig, paired_run
from pilworld.paired.operator import UnattendedOperator
from pilworld.paired.policy_metadata import METADATA_FILE, reset_pose
from pilworld.policies.base import PolicyError
from pilworld.starts.sources import PAIRED_STARTS
from pilworld.types import ChunkSpec
from simrig.poses import HOME_Q14
from tests.pilworld.cli.faulty_server import FaultyServer, free_port

FAKE = "configs/rig/fake_dual_ur5e.yaml"
SIM = "configs/rig/sim_dual_ur5e.yaml"
CKPT = "scripted_step_30k"
START = np.asarray(HOME_Q14, dtype=np.float64)
# A pose near home: the left shoulder pan 0.15 rad further, the right wrist 0.1 rad; grippers open.
TRAINED = START.copy()
TRAINED[0] += 0.15
TRAINED[12] += 0.1


def test_fourteen_twelve_or_six_values() -> None:
    assert reset_pose(CKPT, {}, START) is None
    assert reset_pose(CKPT, {"reset_pose": None}, START) is None
    np.testing.assert_array_equal(reset_pose(CKPT, {"reset_pose": TRAINED.tolist()}, START), TRAINED)
    arms = np.r_[TRAINED[0:6], TRAINED[7:13]]
    twelve = reset_pose(CKPT, {"reset_pose": arms.tolist()}, START)
    assert twelve is not None
    np.testing.assert_array_equal(twelve[[0, 1, 2, 3, 4, 5, 7, 8, 9, 10, 11, 12]], arms)
    assert twelve[6] == START[6] and twelve[13] == START[13]  # grippers stay as the rig starts them
    six = reset_pose(CKPT, {"reset_pose": TRAINED[:6].tolist()}, START)
    assert six is not None
    np.testing.assert_array_equal(six[0:6], TRAINED[:6])
    np.testing.assert_array_equal(six[7:13], TRAINED[:6])  # one arm's pose for both (openpi's ALOHA)


@pytest.mark.parametrize(
    ("value", "why"),
    [
        ([0.1] * 7, "has 7 values"),
        ([float("nan")] * 6, "non-finite"),
        ("home", "is not a list of numbers"),
        ([[0.0] * 6, [0.0] * 6], "has shape"),
        ([*START[:6], 2.0, *START[7:]], "gripper openings"),
    ],
)
def test_bad_reset_poses_are_named(value: object, why: str) -> None:
    with pytest.raises(PolicyError, match=why) as caught:
        reset_pose(CKPT, {"reset_pose": value}, START)
    assert caught.value.kind == "invalid metadata"


def test_the_fake_rig_starts_from_the_servers_reset_pose(tmp_path: Path) -> None:
    out = tmp_path / "run"
    with FaultyServer(FAKE, CKPT, free_port(), extra_metadata={"reset_pose": TRAINED.tolist()}) as server:
        cfg = PairedConfig(
            rig=FAKE, task="sort_cubes", checkpoints=[server.url], subtasks=1, out=str(out), spec=ChunkSpec(rounds=1)
        )
        summary = paired_run(cfg, progress=False, operator=UnattendedOperator())
    assert summary["branches_run"] == 2
    assert (out / METADATA_FILE).is_file()
    start = EpisodeStore(out / PAIRED_STARTS).load(0)
    arms = [0, 1, 2, 3, 4, 5, 7, 8, 9, 10, 11, 12]
    # The arms stood at the server's pose (not the rig's start pose) while the start was recorded.
    np.testing.assert_allclose(start.state[-1][arms], TRAINED[arms], atol=2e-3)
    assert abs(float(start.state[-1][0]) - START[0]) > 0.1


def test_the_simulator_says_it_does_not_apply_it(tmp_path: Path, capfd: pytest.CaptureFixture[str]) -> None:
    out = tmp_path / "run"
    with FaultyServer(SIM, CKPT, free_port(), extra_metadata={"reset_pose": TRAINED.tolist()}) as server:
        cfg = PairedConfig(
            rig=SIM, task="sort_cubes", checkpoints=[server.url], subtasks=1, out=str(out), spec=ChunkSpec(rounds=1)
        )
        paired_run(cfg, progress=False)
    err = capfd.readouterr().err
    assert f"checkpoint {server.url}: the server's reset_pose is not applied on the simulated rig" in err, err
    start = EpisodeStore(out / PAIRED_STARTS).load(0)
    assert abs(float(start.state[-1][0]) - TRAINED[0]) > 0.1  # the arms started at home
