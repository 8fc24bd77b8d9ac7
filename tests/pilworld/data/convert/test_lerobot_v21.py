"""LeRobot v2.1 → our store: exact round trips (lossless), names, tasks, mapping and resize, errors."""

from __future__ import annotations

import json
from pathlib import Path

import cv2
import numpy as np
import pytest

from pilworld.data.convert import ConvertMapping, convert
from pilworld.data.reader import EpisodeStore

from .sources import make_episodes, write_v21

CAMS = {"observation.images.cam_high": (32, 32), "observation.images.cam_left_wrist": (24, 32)}
TASKS = ["pick up the cube.", "stack the bowls."]


def test_round_trip_is_exact(tmp_path: Path) -> None:
    eps = make_episodes([6, 9], CAMS, state_dim=6, action_dim=7, tasks=[0, 1])
    eps[1].task_indices = [1] * 5 + [0] * 4  # the task changes mid-episode: first one wins, all are kept
    names = {"observation.state": [f"j{i}" for i in range(6)], "action": {"motors": [f"m{i}" for i in range(7)]}}
    src = write_v21(tmp_path / "src", eps, TASKS, fps=15, names=names)

    summary = convert(src, tmp_path / "out", video_mode="lossless", progress=False)
    assert summary["format"] == "lerobot-v21" and summary["episodes"] == 2 and summary["frames"] == 15
    assert summary["views"] == {"cam_high": [32, 32], "cam_left_wrist": [24, 32]}
    store = EpisodeStore(tmp_path / "out")
    assert store.spec.fps == 15 and store.spec.robot_type == "test_bot"
    assert store.spec.state_names == tuple(f"j{i}" for i in range(6))
    assert store.spec.action_names == tuple(f"m{i}" for i in range(7))  # v2.0-style {"motors": [...]}
    for k, src_ep in enumerate(eps):
        ep = store.load(k)
        np.testing.assert_array_equal(ep.state, src_ep.state)
        np.testing.assert_array_equal(ep.action, src_ep.action)
        for key, frames in src_ep.images.items():
            np.testing.assert_array_equal(ep.images[key.removeprefix("observation.images.")], frames)
        assert ep.origin == "real"
        assert ep.extra["converted_from"] == {"format": "lerobot-v21", "episode": k}
    assert store.load(0).task == TASKS[0]
    assert store.load(1).task == TASKS[1] and store.load(1).extra["tasks"] == [TASKS[1], TASKS[0]]


def test_17d_actions_two_cameras_mapping_and_resize(tmp_path: Path) -> None:
    """RealSource World shape: any camera keys, 17-d actions; cameras renamed, one dropped, all resized."""
    cams = {
        "observation.images.head": (40, 64),
        "observation.images.hand_left": (40, 64),
        "observation.images.x": (8, 8),
    }
    eps = make_episodes([5, 4], cams, state_dim=17, action_dim=17, tasks=[0])
    src = write_v21(tmp_path / "src", eps, TASKS[:1])
    mapping = ConvertMapping(
        cameras={"observation.images.head": "observation.images.cam_high", "hand_left": "cam_left_wrist"},
        resize=(20, 32),
        origin="imagined",
    )
    convert(src, tmp_path / "out", mapping, video_mode="lossless", progress=False)
    store = EpisodeStore(tmp_path / "out")
    assert store.spec.views == {"cam_high": (20, 32), "cam_left_wrist": (20, 32)}
    assert store.spec.action_names == tuple(f"action_{i}" for i in range(17))  # no names in the source
    for k, src_ep in enumerate(eps):
        ep = store.load(k)
        assert ep.action.shape == (src_ep.length, 17) and ep.origin == "imagined"
        np.testing.assert_array_equal(ep.action, src_ep.action)
        for key, view in (("observation.images.head", "cam_high"), ("observation.images.hand_left", "cam_left_wrist")):
            want = np.stack([cv2.resize(f, (32, 20), interpolation=cv2.INTER_AREA) for f in src_ep.images[key]])
            np.testing.assert_array_equal(ep.images[view], want)


def test_image_features_and_v20(tmp_path: Path) -> None:
    """Older datasets keep a camera as PNG bytes inside the parquet (dtype image); v2.0 reads the same."""
    eps = make_episodes([4, 3], {"observation.images.top": (16, 16), "observation.image": (16, 24)}, 2, 2, [0])
    for e in eps:
        e.image_keys = ("observation.image",)
    src = write_v21(tmp_path / "src", eps, TASKS[:1], version="v2.0")
    convert(src, tmp_path / "out", video_mode="lossless", progress=False)
    store = EpisodeStore(tmp_path / "out")
    assert set(store.spec.views) == {"top", "image"}  # 'observation.image' → 'image'
    for k, src_ep in enumerate(eps):
        np.testing.assert_array_equal(store.frames(k, "image"), src_ep.images["observation.image"])
        np.testing.assert_array_equal(store.frames(k, "top"), src_ep.images["observation.images.top"])


@pytest.fixture
def v21(tmp_path: Path) -> Path:
    return write_v21(tmp_path / "src", make_episodes([4, 5], CAMS, 3, 3, [0]), TASKS[:1])


def test_unknown_camera_lists_available(v21: Path, tmp_path: Path) -> None:
    with pytest.raises(ValueError, match=r"info.json: camera 'cam_top' not in the source \(available: \['observation"):
        convert(v21, tmp_path / "out", ConvertMapping(cameras={"cam_top": "top"}), progress=False)
    assert not (tmp_path / "out").exists()  # nothing created before the source checks out


def test_missing_state_key(v21: Path, tmp_path: Path) -> None:
    with pytest.raises(ValueError, match=r"info.json: no feature 'observation.qpos' for the state \(features: \["):
        convert(v21, tmp_path / "out", ConvertMapping(state_key="observation.qpos"), progress=False)


def test_inconsistent_length(v21: Path, tmp_path: Path) -> None:
    lines = (v21 / "meta/episodes.jsonl").read_text().splitlines()
    row = json.loads(lines[1])
    lines[1] = json.dumps({**row, "length": 7})
    (v21 / "meta/episodes.jsonl").write_text("\n".join(lines))
    with pytest.raises(ValueError, match=r"episode_000001.parquet: 5 rows, but meta/episodes.jsonl gives .* length 7"):
        convert(v21, tmp_path / "out", video_mode="lossless", progress=False)
    assert EpisodeStore(tmp_path / "out").num_episodes == 1  # episode 0 is committed: a rerun resumes


def test_missing_video_and_bad_jsonl(v21: Path, tmp_path: Path) -> None:
    (v21 / "videos/chunk-000/observation.images.cam_high/episode_000000.mp4").unlink()
    with pytest.raises(ValueError, match=r"cam_high/episode_000000.mp4: video file missing"):
        convert(v21, tmp_path / "out", progress=False)
    (v21 / "meta/tasks.jsonl").write_text('{"task_index": 0, "task": "a"}\n{oops\n')
    with pytest.raises(ValueError, match=r"tasks.jsonl:2: not valid JSON"):
        convert(v21, tmp_path / "out2", progress=False)
