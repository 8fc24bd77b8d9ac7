"""``convert``: format detection, resuming an interrupted conversion, output checks, the CLI handler."""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np
import pytest

from pilworld.cli.data_convert import FORMAT_CHOICES, add_convert_parser
from pilworld.data.convert import FORMATS, ConvertMapping, convert, detect_format
from pilworld.data.convert.aloha_hdf5 import AlohaHdf5Source
from pilworld.data.episode import Episode
from pilworld.data.reader import EpisodeStore

from .sources import make_episodes, write_aloha, write_v21, write_v30_packed

TASK = ConvertMapping(task="transfer the cube.")
CAMS = {"observation.images.top": (16, 16)}


@pytest.fixture
def aloha(tmp_path: Path) -> Path:
    for n in range(4):
        write_aloha(tmp_path / "src" / f"episode_{n}.hdf5", T=3 + n, seed=n, cams=("cam_high", "cam_low"))
    return tmp_path / "src"


def test_detect_format(tmp_path: Path, aloha: Path) -> None:
    eps = make_episodes([3], CAMS, 2, 2, [0])
    assert detect_format(write_v21(tmp_path / "v21", eps, ["t"])) == "lerobot-v21"
    assert detect_format(write_v30_packed(tmp_path / "v30", eps, ["t"])) == "lerobot-v30"
    assert detect_format(aloha) == "aloha-hdf5" and detect_format(aloha / "episode_0.hdf5") == "aloha-hdf5"
    assert FORMAT_CHOICES == FORMATS
    (tmp_path / "empty").mkdir()
    with pytest.raises(ValueError, match=r"empty: unknown format: no meta/info.json \(LeRobot\) and no .hdf5 files"):
        detect_format(tmp_path / "empty")
    (tmp_path / "notes.txt").write_text("x")
    with pytest.raises(ValueError, match=r"notes.txt: unknown format \(a single file must be an ALOHA .hdf5"):
        detect_format(tmp_path / "notes.txt")
    info = tmp_path / "v21/meta/info.json"
    info.write_text(info.read_text().replace('"v2.1"', '"v1.6"'))
    with pytest.raises(ValueError, match=r"info.json: codebase_version 'v1.6' is not supported"):
        detect_format(tmp_path / "v21")
    with pytest.raises(ValueError, match=r"nowhere: no such file or folder"):
        convert(tmp_path / "nowhere", tmp_path / "out", progress=False)
    with pytest.raises(ValueError, match=r"info.json: codebase_version 'v3.0'; this importer reads \['v2.0', 'v2.1'\]"):
        convert(tmp_path / "v30", tmp_path / "out", fmt="lerobot-v21", progress=False)
    with pytest.raises(ValueError, match=r"format: expected one of .*got 'rlds'"):
        convert(aloha, tmp_path / "out", TASK, fmt="rlds", progress=False)


def test_resume_after_interruption(tmp_path: Path, aloha: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    reference = convert(aloha, tmp_path / "ref", TASK, "lossless", progress=False)
    loaded: list[int] = []
    original = AlohaHdf5Source._load

    def flaky(self: AlohaHdf5Source, position: int) -> Episode:
        loaded.append(position)
        if position == 2 and len(loaded) == 3:  # the first run dies while reading episode 2
            raise KeyboardInterrupt
        return original(self, position)

    monkeypatch.setattr(AlohaHdf5Source, "_load", flaky)
    with pytest.raises(KeyboardInterrupt):
        convert(aloha, tmp_path / "out", TASK, "lossless", progress=False)
    assert EpisodeStore(tmp_path / "out").num_episodes == 2

    loaded.clear()
    summary = convert(aloha, tmp_path / "out", TASK, "lossless", progress=False)
    assert loaded == [2, 3]  # committed episodes are neither decoded nor written again
    assert (summary["skipped"], summary["converted"], summary["episodes"]) == (2, 2, 4)
    assert summary["frames"] == reference["frames"]
    out, ref = EpisodeStore(tmp_path / "out"), EpisodeStore(tmp_path / "ref")
    for k in range(4):
        a, b = out.load(k), ref.load(k)
        np.testing.assert_array_equal(a.state, b.state)
        np.testing.assert_array_equal(a.images["cam_low"], b.images["cam_low"])
        assert a.extra == b.extra

    again = convert(aloha, tmp_path / "out", TASK, "lossless", progress=False)  # nothing left to do
    assert (again["skipped"], again["converted"]) == (4, 0)


def test_resume_refuses_other_spec_or_source(tmp_path: Path, aloha: Path) -> None:
    convert(aloha, tmp_path / "out", TASK, "lossless", progress=False)
    with pytest.raises(
        ValueError, match=r"out: exists with a different spec \(video_mode: 'lossless' there, 'h264' now"
    ):
        convert(aloha, tmp_path / "out", TASK, "h264", progress=False)
    with pytest.raises(ValueError, match=r"views: .* there, .* now.*resume with the same mapping"):
        convert(aloha, tmp_path / "out", TASK.with_overrides(resize=(8, 8)), "lossless", progress=False)
    other = tmp_path / "other"
    for n in range(2):  # same layout, other lengths: another source, refused (it would be mixed in)
        write_aloha(other / f"episode_{n}.hdf5", T=9, seed=n, cams=("cam_high", "cam_low"))
    before = sorted((p.relative_to(tmp_path), p.stat().st_size) for p in (tmp_path / "out").rglob("*"))
    with pytest.raises(
        ValueError, match=r"out: holds a conversion of .*src \(4 episodes\); .*other is another source: pass --append"
    ):
        convert(other, tmp_path / "out", TASK, "lossless", progress=False)
    assert sorted((p.relative_to(tmp_path), p.stat().st_size) for p in (tmp_path / "out").rglob("*")) == before


def test_append_adds_another_source_after_the_first(tmp_path: Path, aloha: Path) -> None:
    """A second source goes in only with --append, after the first's episodes; each source resumes by itself."""
    import json

    out = tmp_path / "out"
    first = convert(aloha, out, TASK, "lossless", progress=False)
    other = tmp_path / "other"
    for n in range(2):
        write_aloha(other / f"episode_{n}.hdf5", T=9, seed=n, cams=("cam_high", "cam_low"))
    second = convert(other, out, TASK, "lossless", progress=False, append=True)
    assert (second["skipped"], second["converted"], second["episodes"]) == (0, 2, first["episodes"] + 2)
    sources = json.loads((out / "conversion.json").read_text())["settings"]["sources"]
    assert [(s["first_episode"], s["episodes"]) for s in sources] == [(0, first["episodes"]), (first["episodes"], 2)]
    again = convert(other, out, TASK, "lossless", progress=False)  # a rerun of either source: nothing to do
    assert (again["skipped"], again["converted"]) == (2, 0)
    assert convert(aloha, out, TASK, "lossless", progress=False)["converted"] == 0
    with pytest.raises(
        ValueError, match=r"--append: .*other is already source 2 of .*out \(episodes 4..5\); rerun without --append"
    ):
        write_aloha(other / "episode_2.hdf5", T=9, seed=2, cams=("cam_high", "cam_low"))
        convert(other, out, TASK, "lossless", progress=False, append=True)


def test_output_checks(tmp_path: Path, aloha: Path) -> None:
    (tmp_path / "busy").mkdir()
    (tmp_path / "busy" / "notes.txt").write_text("mine")
    with pytest.raises(ValueError, match=r"OUT: .*busy holds files of no pilworld run.*choose a new or empty OUT"):
        convert(aloha, tmp_path / "busy", TASK, progress=False)
    with pytest.raises(ValueError, match=r"the output must not be the source or inside it"):
        convert(aloha, aloha / "converted", TASK, progress=False)
    with pytest.raises(ValueError, match=r"mapping field 'resize': h264 needs an even size, got \[15, 16\]"):
        convert(aloha, tmp_path / "out", TASK.with_overrides(resize=(15, 16)), progress=False)
    odd = tmp_path / "odd.hdf5"
    write_aloha(odd, T=2, seed=0, cams=("top",), size=(15, 16))
    with pytest.raises(ValueError, match=r"odd.hdf5: views: h264 needs even image sizes, got \{'top': \(15, 16\)\}"):
        convert(odd, tmp_path / "out", TASK, progress=False)
    with pytest.raises(ValueError, match=r"video codec mode: expected one of"):
        convert(aloha, tmp_path / "out", TASK, video_mode="mjpeg", progress=False)
    assert not (tmp_path / "out").exists()


def _cli(argv: list[str]) -> int:
    parser = argparse.ArgumentParser(prog="pilworld data")
    add_convert_parser(parser.add_subparsers(dest="data_command"))
    args = parser.parse_args(argv)
    return int(args.handler(args))


def test_cli(tmp_path: Path, aloha: Path, capsys: pytest.CaptureFixture[str]) -> None:
    mapping = tmp_path / "map.yaml"
    mapping.write_text("cameras: {cam_low: low}\nresize: [8, 8]\ntask: from the file\n")
    argv = ["convert", str(aloha), str(tmp_path / "out"), "--mapping", str(mapping), "--task", "from the flag"]
    assert _cli([*argv, "--video-mode", "lossless", "--json"]) == 0
    lines = capsys.readouterr().out.strip().splitlines()
    summary = json.loads(lines[-1])
    assert lines[0].startswith("convert: 4 episodes (18 frames) from aloha-hdf5 ") and "low 8x8" in lines[0]
    assert summary["views"] == {"low": [8, 8]} and summary["video_mode"] == "lossless" and summary["converted"] == 4
    assert EpisodeStore(tmp_path / "out").load(0).task == "from the flag"  # --task overrides the mapping's
    assert _cli([*argv, "--video-mode", "lossless"]) == 0
    assert "4 already there" in capsys.readouterr().out
