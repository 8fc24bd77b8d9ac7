"""Episode store: round trips, recovery after a crash, appending, errors."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pyarrow.parquet as pq
import pytest

from pilworld.data import layout
from pilworld.data.episode import Episode
from pilworld.data.reader import DatasetError, EpisodeStore
from pilworld.data.spec import DatasetSpec
from pilworld.data.writer import EpisodeWriter

from .conftest import VIEWS, make_episode

SPEC = {"views": {v: (32, 48) for v in VIEWS}}


# Stated tolerances for the lossy modes on smooth content: PSNR > 38 dB and mean |error| < 2 levels for h264
# (the YUV 4:2:0 conversion alone costs ~1.5 levels), < 2.5 for av1: at CRF 30 (LeRobot's setting) on these
# 48×32 frames, where SVT-AV1 turns off its adaptive quantisation and restoration filter, SVT-AV1 4.1 (PyAV 18.1.0)
# gives 1.1–1.6 levels and 4.3 (PyAV 18.1.1) 1.5–2.03 (PSNR 40.3–41.4 dB).
MEAN_ERROR = {"h264": 2.0, "av1": 2.5}


@pytest.mark.parametrize("mode", ["lossless", "h264", "av1"])
def test_round_trip(tmp_path: Path, episodes: list[Episode], mode: str) -> None:
    with EpisodeWriter(tmp_path / "ds", DatasetSpec(video_mode=mode, **SPEC)) as w:  # type: ignore[arg-type]
        assert [w.append(e) for e in episodes] == [0, 1, 2]
    store = EpisodeStore(tmp_path / "ds")
    assert store.num_episodes == 3 and store.num_frames == sum(e.length for e in episodes)
    for i, ep in enumerate(episodes):
        back = store.load(i)
        np.testing.assert_array_equal(back.state, ep.state)  # bit-exact
        np.testing.assert_array_equal(back.action, ep.action)
        assert back.state.dtype == np.float32 and back.action.dtype == np.float32
        assert (back.task, back.origin, back.subtask_index, back.checkpoint, back.seed) == (
            ep.task,
            ep.origin,
            ep.subtask_index,
            ep.checkpoint,
            ep.seed,
        )
        np.testing.assert_array_equal(back.rounds(), ep.rounds())
        for v in VIEWS:
            diff = np.abs(back.images[v].astype(int) - ep.images[v].astype(int))
            if mode == "lossless":
                assert diff.max() == 0
            else:
                psnr = 10 * np.log10(255**2 / max((diff.astype(float) ** 2).mean(), 1e-12))
                why = f"{mode} {v}: mean {diff.mean():.2f}, PSNR {psnr:.1f} dB"
                assert diff.mean() < MEAN_ERROR[mode] and psnr > 38, why
        # A slice decodes the same frames as the whole episode.
        np.testing.assert_array_equal(store.frames(i, "cam_high", start=5, count=4), back.images["cam_high"][5:9])


def test_layout_and_metadata(tmp_path: Path, episodes: list[Episode]) -> None:
    root = tmp_path / "ds"
    with EpisodeWriter(root, DatasetSpec(video_mode="lossless", **SPEC)) as w:  # type: ignore[arg-type]
        for e in episodes:
            w.append(e)
    info = json.loads((root / layout.INFO).read_text())
    assert info["codebase_version"] == "v3.0" and info["total_episodes"] == 3 and info["total_tasks"] == 2
    assert info["total_frames"] == sum(e.length for e in episodes)
    assert info["features"]["observation.images.cam_high"]["dtype"] == "video"
    assert info["features"]["observation.state"]["shape"] == [14]
    for key in ("origin", "subtask_index", "round_index", "checkpoint", "seed"):
        assert key in info["features"]
    data = pq.read_table(root / "data/chunk-000/file-001.parquet").to_pydict()
    assert data["episode_index"] == [1] * episodes[1].length
    assert data["index"][0] == episodes[0].length  # global frame index continues
    assert set(data["origin"]) == {"imagined"}
    rows = pq.read_table(root / "meta/episodes/chunk-000/file-000.parquet").to_pylist()
    assert [r["dataset_from_index"] for r in rows] == [0, episodes[0].length, episodes[0].length + episodes[1].length]
    assert rows[2]["videos/observation.images.cam_left_wrist/file_index"] == 2
    # LeRobot reads the task as the pandas index of tasks.parquet (row = task_index).
    tasks = pq.read_table(root / layout.TASKS)
    assert tasks.schema.pandas_metadata["index_columns"] == ["__index_level_0__"]
    assert tasks.column("__index_level_0__").to_pylist() == [episodes[0].task, episodes[1].task]
    stats = json.loads((root / layout.STATS).read_text())
    all_state = np.concatenate([e.state for e in episodes])
    np.testing.assert_allclose(stats["observation.state"]["mean"], all_state.mean(axis=0), atol=1e-6)
    np.testing.assert_allclose(stats["observation.state"]["std"], all_state.std(axis=0), atol=1e-6)
    assert np.array(stats["observation.images.cam_high"]["mean"]).shape == (3, 1, 1)


def test_reopen_appends_with_consistent_indices(tmp_path: Path, episodes: list[Episode]) -> None:
    root = tmp_path / "ds"
    spec = DatasetSpec(video_mode="lossless", **SPEC)  # type: ignore[arg-type]
    with EpisodeWriter(root, spec) as w:
        w.append(episodes[0])
    with EpisodeWriter(root) as w:  # spec read back from the dataset
        assert w.num_episodes == 1
        assert w.append(episodes[1]) == 1
    store = EpisodeStore(root)
    assert store.num_episodes == 2
    assert store.episodes[1]["dataset_from_index"] == episodes[0].length
    np.testing.assert_array_equal(store.load(1).state, episodes[1].state)


def test_recovery_removes_uncommitted_files(tmp_path: Path, episodes: list[Episode]) -> None:
    root = tmp_path / "ds"
    spec = DatasetSpec(video_mode="lossless", **SPEC)  # type: ignore[arg-type]
    with EpisodeWriter(root, spec) as w:
        w.append(episodes[0])
    # What a writer killed during episode 1 leaves: its data file, one video, a temp file.
    (root / "data/chunk-000/file-001.parquet").write_bytes(b"partial")
    stray = root / "videos/observation.images.cam_high/chunk-000/file-001.mp4"
    stray.write_bytes(b"partial")
    (root / "meta/info.json.tmp-999").write_text("{")
    assert EpisodeStore(root).num_episodes == 1  # readers never see it
    with EpisodeWriter(root) as w:
        assert w.recovered_files == 3
        assert not stray.exists()
        assert w.append(episodes[2]) == 1
    back = EpisodeStore(root).load(1)
    np.testing.assert_array_equal(back.images["cam_high"], episodes[2].images["cam_high"])


def test_one_writer_at_a_time(tmp_path: Path) -> None:
    spec = DatasetSpec(**SPEC)  # type: ignore[arg-type]
    with EpisodeWriter(tmp_path / "ds", spec), pytest.raises(DatasetError, match="another writer"):
        EpisodeWriter(tmp_path / "ds")


def test_spec_mismatch_and_missing(tmp_path: Path) -> None:
    with EpisodeWriter(tmp_path / "ds", DatasetSpec(**SPEC)):  # type: ignore[arg-type]
        pass
    with pytest.raises(DatasetError, match="different spec"):
        EpisodeWriter(tmp_path / "ds", DatasetSpec(fps=50, **SPEC))  # type: ignore[arg-type]
    with pytest.raises(DatasetError, match="pass a DatasetSpec"):
        EpisodeWriter(tmp_path / "new")
    with pytest.raises(DatasetError, match="not a LeRobot dataset"):
        EpisodeStore(tmp_path / "nothing")


@pytest.mark.parametrize(
    ("change", "message"),
    [
        ({"state": np.zeros((5, 13), np.float32)}, r"state: expected shape \(N×14\)"),
        ({"action": np.zeros((4, 14), np.float32)}, r"action: expected shape \(5×14\)"),
        ({"images": {"cam_high": np.zeros((5, 32, 48, 3), np.uint8)}}, "images: expected views"),
        ({"origin": "dreamed"}, "origin: expected one of"),
        ({"task": " "}, "task: expected a non-empty instruction"),
        ({"round_index": np.arange(4)}, "round_index: expected 5"),
    ],
)
def test_bad_episode_is_rejected_before_writing(tmp_path: Path, change: dict[str, object], message: str) -> None:
    good = make_episode(5, 0)
    fields = {
        "images": good.images,
        "state": good.state,
        "action": good.action,
        "task": good.task,
        "round_index": good.round_index,
    }
    fields.update(change)
    bad = Episode(**fields)  # type: ignore[arg-type]
    with EpisodeWriter(tmp_path / "ds", DatasetSpec(**SPEC)) as w:  # type: ignore[arg-type]
        with pytest.raises(ValueError, match=message):
            w.append(bad)
        assert w.num_episodes == 0
    assert not list((tmp_path / "ds").glob("data/**/*.parquet"))


def test_spec_validation() -> None:
    with pytest.raises(ValueError, match="even image sizes"):
        DatasetSpec(views={"cam_high": (31, 48)})
    DatasetSpec(views={"cam_high": (31, 48)}, video_mode="lossless")
    with pytest.raises(ValueError, match="video_mode: expected one of"):
        DatasetSpec(video_mode="mjpeg")
    with pytest.raises(ValueError, match="camera key"):
        DatasetSpec(views={"cam high": (32, 32)})
