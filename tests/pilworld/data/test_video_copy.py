"""Copying an episode's videos byte for byte (``EpisodeWriter.append(video_files=…)``) instead of
re-encoding them, as ``real_from`` does for every shared real branch."""

from __future__ import annotations

from pathlib import Path

import pytest

from pilworld.data.episode import Episode
from pilworld.data.reader import EpisodeStore
from pilworld.data.spec import IMAGE_PREFIX, DatasetSpec
from pilworld.data.writer import EpisodeWriter

from .conftest import VIEWS

SPEC = DatasetSpec(video_mode="lossless", views={v: (32, 48) for v in VIEWS})


@pytest.fixture
def source(tmp_path: Path, episodes: list[Episode]) -> EpisodeStore:
    with EpisodeWriter(tmp_path / "src", SPEC) as w:
        for ep in episodes:
            w.append(ep)
    return EpisodeStore(tmp_path / "src")


def test_copied_videos_are_the_source_files_and_decode_to_the_same_frames(source: EpisodeStore, tmp_path: Path) -> None:
    ep = source.load(2)
    files = {v: source.own_video_file(2, v) for v in VIEWS}
    assert all(p is not None for p in files.values())
    with EpisodeWriter(tmp_path / "dst", SPEC) as w:
        assert w.append(ep, video_files={v: p for v, p in files.items() if p is not None}) == 0
    dst = EpisodeStore(tmp_path / "dst")
    for v in VIEWS:
        copied, _ = dst.video_file(0, v)
        assert copied.read_bytes() == files[v].read_bytes(), v  # type: ignore[union-attr]
        assert dst.frames(0, v).tobytes() == ep.images[v].tobytes(), v
    # The statistics are the episode's own, as if it had been encoded here.
    assert (
        dst.episodes[0]["stats/observation.images.cam_high/mean"]
        == source.episodes[2]["stats/observation.images.cam_high/mean"]
    )


def test_a_file_shared_by_several_episodes_is_not_offered(source: EpisodeStore) -> None:
    """LeRobot conversions may pack episodes into one mp4: copying it would copy the others too."""
    key = IMAGE_PREFIX + "cam_high"
    for col in (f"videos/{key}/chunk_index", f"videos/{key}/file_index"):
        source.episodes[1][col] = source.episodes[0][col]
    assert source.own_video_file(0, "cam_high") is None
    assert source.own_video_file(1, "cam_high") is None
    assert source.own_video_file(0, "cam_left_wrist") is not None
    source.episodes[2][f"videos/{key}/from_timestamp"] = 1.0  # not at the file's start
    assert source.own_video_file(2, "cam_high") is None


def test_bad_video_files_are_refused_before_anything_is_written(
    source: EpisodeStore, tmp_path: Path, episodes: list[Episode]
) -> None:
    with EpisodeWriter(tmp_path / "dst", SPEC) as w:
        with pytest.raises(ValueError, match="'cam_top' is not a view"):
            w.append(episodes[0], video_files={"cam_top": tmp_path})
        with pytest.raises(FileNotFoundError, match="cam_high"):
            w.append(episodes[0], video_files={"cam_high": tmp_path / "nowhere.mp4"})
        assert w.append(episodes[0]) == 0  # the writer is still usable, and nothing was committed before
    assert EpisodeStore(tmp_path / "dst").num_episodes == 1
