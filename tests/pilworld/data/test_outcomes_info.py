"""Outcomes sidecar and `data info`."""

from __future__ import annotations

import datetime as dt
import json
from pathlib import Path

import pytest

from pilworld.cli.main import main
from pilworld.data.info import dataset_info
from pilworld.data.outcomes import Outcome, read_outcomes, record_outcomes, summarize
from pilworld.data.spec import DatasetSpec
from pilworld.data.writer import EpisodeWriter

from .conftest import VIEWS, make_episode


def test_outcomes_upsert_and_summary(tmp_path: Path) -> None:
    t = dt.datetime(2026, 11, 1, tzinfo=dt.UTC)
    record_outcomes(tmp_path, [Outcome(0, "alice", "human", True, 45, judged_at=t, judge_seconds=12.5)])
    n = record_outcomes(
        tmp_path,
        [
            Outcome(0, "alice", "human", False, 45, first_hallucination_frame=9, judged_at=t),  # replaces
            Outcome(1, "alice", "human", True, 45, judged_at=t),
            Outcome(0, "sim_state", "sim_state", True, 45, judged_at=t),
        ],
    )
    assert n == 3
    rows = read_outcomes(tmp_path)
    assert [(o.episode_index, o.judge_id, o.success) for o in rows] == [
        (0, "alice", False),
        (0, "sim_state", True),
        (1, "alice", True),
    ]
    assert rows[0].judged_at == t and rows[0].first_hallucination_frame == 9
    s = summarize(rows)
    assert s["alice"]["success_rate"] == 0.5
    assert s["alice"]["hallucination_free_ratio"] == pytest.approx((9 / 45 + 1.0) / 2)


@pytest.mark.parametrize(
    ("kwargs", "message"),
    [
        ({"judge_kind": "oracle"}, "judge_kind: expected one of"),
        ({"first_hallucination_frame": 45}, r"first_hallucination_frame: expected None or an integer in \[0, 45\)"),
        ({"num_frames": 0}, "num_frames: expected an integer >= 1"),
        ({"success": 1}, "success: expected True or False"),
        ({"judge_id": ""}, "judge_id"),
    ],
)
def test_outcome_validation(kwargs: dict[str, object], message: str) -> None:
    base: dict[str, object] = {
        "episode_index": 0,
        "judge_id": "j",
        "judge_kind": "human",
        "success": True,
        "num_frames": 45,
    }
    with pytest.raises(ValueError, match=message):
        Outcome(**{**base, **kwargs})  # type: ignore[arg-type]


def test_outcomes_for_missing_episodes_are_rejected(tmp_path: Path) -> None:
    with pytest.raises(ValueError, match=r"episode_index: \[5\] not in"):
        record_outcomes(tmp_path, [Outcome(5, "j", "human", True, 10)], num_episodes=3)
    assert read_outcomes(tmp_path) == []


def test_data_info(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    root = tmp_path / "ds"
    with EpisodeWriter(root, DatasetSpec(views={v: (32, 48) for v in VIEWS})) as w:
        for k in range(3):
            w.append(make_episode(20, k, origin=("real", "imagined")[k % 2]))
    record_outcomes(root, [Outcome(0, "sim_state", "sim_state", True, 20)], num_episodes=3)
    info = dataset_info(root)
    assert info["episodes"] == 3 and info["frames"] == 60 and info["fps"] == 30 and info["action_dim"] == 14
    assert info["by_origin"] == {"imagined": {"episodes": 1, "frames": 20}, "real": {"episodes": 2, "frames": 40}}
    assert info["cameras"]["cam_high"] == {"height": 32, "width": 48}
    assert info["outcomes"]["sim_state"]["success_rate"] == 1.0
    assert main(["data", "info", str(root), "--json"]) == 0
    out = capsys.readouterr().out.strip().splitlines()
    assert json.loads(out[-1])["episodes"] == 3 and "3 episodes, 60 frames at 30 fps" in out[0]
    assert main(["data", "info", str(tmp_path / "none")]) == 2
    assert "not a LeRobot dataset" in capsys.readouterr().err
