"""LeRobot v3.0 → our store: a packed dataset (shared parquet and mp4s), our own datasets, mapping."""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import cv2
import numpy as np
import pyarrow.parquet as pq
import pytest

from pilworld.data.convert import ConvertMapping, convert
from pilworld.data.episode import Episode
from pilworld.data.reader import EpisodeStore
from pilworld.data.spec import DatasetSpec
from pilworld.data.writer import EpisodeWriter

from ..conftest import VIEWS, make_episode
from .sources import SourceEpisode, make_episodes, write_v30_packed

CAMS = {"observation.images.top": (32, 32), "observation.images.wrist": (16, 32)}
TASKS = ["fold the towel.", "open the drawer."]
Packed = tuple[Path, list[SourceEpisode]]


@pytest.fixture
def packed(tmp_path: Path) -> Packed:
    # 46 frames: episode 2 starts past the key frame at 30 (GOP 30), so the decoder seeks to it.
    eps = make_episodes([5, 37, 4], CAMS, state_dim=14, action_dim=14, tasks=[0, 1, 0])
    return write_v30_packed(tmp_path / "src", eps, TASKS, fps=20), eps


def test_packed_round_trip_is_exact(packed: Packed, tmp_path: Path) -> None:
    src, eps = packed
    rows = pq.read_table(src / "meta/episodes/chunk-000/file-000.parquet").to_pylist()
    assert {r["data/file_index"] for r in rows} == {0} and rows[2]["videos/observation.images.top/from_timestamp"] > 0

    summary = convert(src, tmp_path / "out", video_mode="lossless", progress=False)
    assert summary["format"] == "lerobot-v30" and summary["converted"] == 3 and summary["frames"] == 46
    store = EpisodeStore(tmp_path / "out")
    assert store.spec.views == {"top": (32, 32), "wrist": (16, 32)} and store.spec.fps == 20
    for k, src_ep in enumerate(eps):
        ep = store.load(k)
        assert ep.length == src_ep.length and ep.task == TASKS[src_ep.task_indices[0]]
        np.testing.assert_array_equal(ep.state, src_ep.state)
        np.testing.assert_array_equal(ep.action, src_ep.action)
        np.testing.assert_array_equal(ep.images["top"], src_ep.images["observation.images.top"])
        np.testing.assert_array_equal(ep.images["wrist"], src_ep.images["observation.images.wrist"])
        # Each file of ours holds one episode: the shared-file offsets were resolved, not copied.
        assert store.video_file(k, "top")[1] == 0.0


def test_packed_select_rename_resize(packed: Packed, tmp_path: Path) -> None:
    src, eps = packed
    mapping = ConvertMapping(cameras={"wrist": "cam_left_wrist"}, resize=(8, 16), fps=10)
    convert(src, tmp_path / "out", mapping, video_mode="lossless", progress=False)
    store = EpisodeStore(tmp_path / "out")
    assert store.spec.views == {"cam_left_wrist": (8, 16)} and store.spec.fps == 10  # relabelled, not resampled
    src_frames = eps[1].images["observation.images.wrist"]
    want = np.stack([cv2.resize(f, (16, 8), interpolation=cv2.INTER_AREA) for f in src_frames])
    np.testing.assert_array_equal(store.frames(1, "cam_left_wrist"), want)


def test_own_dataset_keeps_labels(tmp_path: Path) -> None:
    """Re-converting one of our datasets (e.g. to resize it) keeps origin, subtask, rounds, seed, extra."""
    spec = DatasetSpec(views={v: (32, 48) for v in VIEWS}, video_mode="lossless")
    episodes: list[Episode] = [
        replace(make_episode(12, k, origin=("real", "imagined")[k]), extra={"note": k}) for k in range(2)
    ]
    with EpisodeWriter(tmp_path / "ours", spec) as w:
        for e in episodes:
            w.append(e)
    convert(tmp_path / "ours", tmp_path / "out", ConvertMapping(resize=(16, 24)), progress=False)
    store = EpisodeStore(tmp_path / "out")
    for k, src_ep in enumerate(episodes):
        ep = store.load(k)
        assert (ep.origin, ep.subtask_index, ep.checkpoint, ep.seed) == (
            src_ep.origin,
            src_ep.subtask_index,
            src_ep.checkpoint,
            src_ep.seed,
        )
        np.testing.assert_array_equal(ep.rounds(), src_ep.rounds())
        assert ep.extra["note"] == k and ep.extra["converted_from"]["format"] == "lerobot-v30"
    assert store.spec.state_names == spec.state_names and store.spec.views["cam_high"] == (16, 24)


def test_missing_video_location(packed: Packed, tmp_path: Path) -> None:
    src, _ = packed
    (src / "videos/observation.images.wrist/chunk-000/file-000.mp4").unlink()
    with pytest.raises(ValueError, match=r"observation.images.wrist/chunk-000/file-000.mp4: video file missing"):
        convert(src, tmp_path / "out", progress=False)
