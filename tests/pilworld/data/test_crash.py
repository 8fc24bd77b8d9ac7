"""Kill test: a writer SIGKILLed in the middle of an episode loses only that episode."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

from pilworld.data.reader import EpisodeStore
from pilworld.data.writer import EpisodeWriter

from .conftest import make_episode

ROOT = Path(__file__).resolve().parents[3]

CHILD = """
import pathlib, sys, time
sys.path.insert(0, sys.argv[3])
import pilworld.data.writer as W
from pilworld.data.spec import DatasetSpec
from tests.pilworld.data.conftest import VIEWS, make_episode

root, signal_file = pathlib.Path(sys.argv[1]), pathlib.Path(sys.argv[2])
w = W.EpisodeWriter(root, DatasetSpec(video_mode="lossless", views={v: (32, 48) for v in VIEWS}))
w.append(make_episode(20, 0))
w.append(make_episode(27, 1))
real_encode = W.encode_video

def encode_then_hang(frames, path, fps, mode):
    real_encode(frames, path, fps, mode)
    signal_file.write_text("mid-episode")  # data parquet and one video of episode 2 are on disk
    time.sleep(120)

W.encode_video = encode_then_hang
w.append(make_episode(34, 2))
"""


def test_sigkill_mid_episode_then_append(tmp_path: Path) -> None:
    root, flag = tmp_path / "ds", tmp_path / "mid"
    child = subprocess.Popen([sys.executable, "-c", CHILD, str(root), str(flag), str(ROOT)])
    try:
        deadline = time.monotonic() + 120
        while not flag.exists():
            assert child.poll() is None, f"writer exited early with {child.returncode}"
            assert time.monotonic() < deadline, "writer never reached the middle of episode 2"
            time.sleep(0.05)
        os.kill(child.pid, signal.SIGKILL)
        child.wait(timeout=30)
    finally:
        if child.poll() is None:
            child.kill()
    assert child.returncode == -signal.SIGKILL
    assert (root / "data/chunk-000/file-002.parquet").exists()  # the half-written episode's leftovers

    store = EpisodeStore(root)
    assert store.num_episodes == 2  # every completed episode, nothing else
    for i, (length, k) in enumerate(((20, 0), (27, 1))):
        ep, expected = store.load(i), make_episode(length, k)
        np.testing.assert_array_equal(ep.state, expected.state)
        np.testing.assert_array_equal(ep.images["cam_right_wrist"], expected.images["cam_right_wrist"])

    with EpisodeWriter(root) as w:  # the lock died with the killed process
        assert w.recovered_files >= 2
        assert w.append(make_episode(15, 5)) == 2
    store = EpisodeStore(root)
    assert store.num_episodes == 3
    assert [r["dataset_from_index"] for r in store.episodes] == [0, 20, 47]
    assert store.info["total_frames"] == 62 and store.info["total_episodes"] == 3
    back = store.load(2)
    np.testing.assert_array_equal(back.state, make_episode(15, 5).state)
    assert back.images["cam_high"].shape == (15, 32, 48, 3)
