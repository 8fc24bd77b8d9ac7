"""ALOHA HDF5 → our store: raw and JPEG-compressed cameras, colour order, numeric file order, errors."""

from __future__ import annotations

from pathlib import Path

import cv2
import h5py
import numpy as np
import pytest

from pilworld.data.convert import ConvertMapping, convert
from pilworld.data.convert.aloha_hdf5 import ALOHA_NAMES
from pilworld.data.reader import EpisodeStore

from .sources import ALOHA_CAMS, write_aloha

TASK = ConvertMapping(task="transfer the cube.")


def test_raw_round_trip_and_numeric_order(tmp_path: Path) -> None:
    src = tmp_path / "src"
    # Written out of order, and 10 sorts before 2 as text: the importer orders by number.
    eps = {n: write_aloha(src / f"episode_{n}.hdf5", T=5 + n % 3, seed=n) for n in (10, 2, 0)}
    summary = convert(src, tmp_path / "out", TASK, video_mode="lossless", progress=False)
    assert summary["format"] == "aloha-hdf5" and summary["fps"] == 50 and summary["episodes"] == 3
    store = EpisodeStore(tmp_path / "out")
    assert set(store.spec.views) == set(ALOHA_CAMS) and store.spec.views["cam_high"] == (32, 32)
    assert store.spec.state_names == ALOHA_NAMES and store.spec.robot_type == "aloha"
    for k, n in enumerate((0, 2, 10)):
        ep = store.load(k)
        assert ep.extra["converted_from"] == {"format": "aloha-hdf5", "episode": k, "file": f"episode_{n}.hdf5"}
        assert ep.task == "transfer the cube." and ep.origin == "real"
        np.testing.assert_array_equal(ep.state, eps[n].qpos)
        np.testing.assert_array_equal(ep.action, eps[n].action)
        for cam in ALOHA_CAMS:
            np.testing.assert_array_equal(ep.images[cam], eps[n].images[cam])


def test_jpeg_compressed(tmp_path: Path) -> None:
    """Decoded exactly as OpenCV decodes the stored JPEGs, and within JPEG error of the RGB originals.

    Tolerance (quality 90, smooth 32×32 content): mean |error| ≤ 3 levels, and ≤ 12 everywhere at least
    4 pixels away from the red square (JPEG's 4:2:0 chroma smears its edge: single pixels there are off
    by ~100, measured 7–8 elsewhere). A red/blue swap would be off by ~220 on the red square.
    """
    src = tmp_path / "src"
    eps = [write_aloha(src / f"episode_{n}.hdf5", T=6, seed=n, compress=True) for n in range(2)]
    with h5py.File(src / "episode_0.hdf5") as f:
        assert f.attrs["compress"] and f["/observations/images/cam_high"].ndim == 2
    convert(src, tmp_path / "out", TASK.with_overrides(fps=25), video_mode="lossless", progress=False)
    store = EpisodeStore(tmp_path / "out")
    assert store.spec.fps == 25
    for k, src_ep in enumerate(eps):
        ep = store.load(k)
        for cam in ALOHA_CAMS:
            decoded = np.stack([np.asarray(cv2.imdecode(j, cv2.IMREAD_COLOR)) for j in src_ep.jpegs[cam]])
            np.testing.assert_array_equal(ep.images[cam], decoded)
            err = np.abs(ep.images[cam].astype(int) - src_ep.images[cam].astype(int))
            assert err.mean() <= 3 and err[:, 12:, 12:].max() <= 12, (cam, err.mean(), err[:, 12:, 12:].max())
            red = ep.images[cam][:, :8, :8].reshape(-1, 3).mean(axis=0)
            assert red[0] > 200 and red[2] < 50  # still red: the channel order survived


def test_bgr_option_and_single_file(tmp_path: Path) -> None:
    src = write_aloha(tmp_path / "one.hdf5", T=4, seed=3, cams=("top",))
    convert(tmp_path / "one.hdf5", tmp_path / "out", TASK.with_overrides(color_order="bgr"), progress=False)
    frames = EpisodeStore(tmp_path / "out").frames(0, "top")
    assert frames.shape == (4, 32, 32, 3)
    convert(
        tmp_path / "one.hdf5", tmp_path / "out2", TASK.with_overrides(color_order="bgr"), "lossless", progress=False
    )
    np.testing.assert_array_equal(EpisodeStore(tmp_path / "out2").frames(0, "top"), src.images["top"][..., ::-1])


def test_mapping_selects_and_resizes(tmp_path: Path) -> None:
    eps = [write_aloha(tmp_path / "src" / f"episode_{n}.hdf5", T=4, seed=n, size=(32, 48)) for n in range(2)]
    mapping = TASK.with_overrides(cameras={"cam_high": "top", "/cam_left_wrist": "left"}, resize=(16, 24))
    convert(tmp_path / "src", tmp_path / "out", mapping, "lossless", progress=False)
    store = EpisodeStore(tmp_path / "out")
    assert store.spec.views == {"top": (16, 24), "left": (16, 24)}
    want = np.stack([cv2.resize(f, (24, 16), interpolation=cv2.INTER_AREA) for f in eps[1].images["cam_high"]])
    np.testing.assert_array_equal(store.frames(1, "top"), want)


def test_errors(tmp_path: Path) -> None:
    src = tmp_path / "src"
    write_aloha(src / "episode_0.hdf5", T=4, seed=0)
    with pytest.raises(ValueError, match=r"src: no instruction in the source; pass --task TEXT or set 'task'"):
        convert(src, tmp_path / "out", progress=False)
    with pytest.raises(ValueError, match=r"episode_0.hdf5:/observations/images: camera 'cam_top' not in the source "):
        convert(src, tmp_path / "out", TASK.with_overrides(cameras={"cam_top": "top"}), progress=False)
    with pytest.raises(ValueError, match=r"no dataset '/observations/effort' for the state \(datasets: \['/action'"):
        convert(src, tmp_path / "out", TASK.with_overrides(state_key="observations/effort"), progress=False)
    with h5py.File(src / "episode_1.hdf5", "w") as f:  # qpos one row short
        write = write_aloha(tmp_path / "tmp.hdf5", T=4, seed=1)
        f.create_dataset("observations/qpos", data=write.qpos[:3])
        f.create_dataset("action", data=write.action)
        for cam, frames in write.images.items():
            f.create_dataset(f"observations/images/{cam}", data=frames)
    with pytest.raises(ValueError, match=r"episode_1.hdf5: /observations/qpos has 3 rows but /action has 4"):
        convert(src, tmp_path / "out", TASK, progress=False)
