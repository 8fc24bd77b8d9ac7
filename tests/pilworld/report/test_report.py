"""``build_report``: the page's structure (parsed with html.parser), embedded media, self-containment, CLI."""

from __future__ import annotations

import argparse
import json
import re
import shutil
from pathlib import Path

import numpy as np
import pytest

from pilworld.cli import report as report_cli
from pilworld.config.rig import RigConfig
from pilworld.control_video.gamma import ControlVideo
from pilworld.data.episode import Episode
from pilworld.data.reader import DatasetError, EpisodeStore
from pilworld.data.video_codec import decode_video as read_video
from pilworld.metrics import write_metrics
from pilworld.report import build_report
from pilworld.report.media import GAP, control_frames
from tests.pilworld.report.conftest import SIM, SPEC, Built
from tests.pilworld.report.page_parse import data_payload, is_mp4, parse, text_of

VIEWS = ["cam_high", "cam_left_wrist", "cam_right_wrist"]


def test_page_has_a_video_per_pair_the_metrics_table_and_the_charts(built: Built) -> None:
    page = parse(built.report.read_text(encoding="utf-8"))
    store = EpisodeStore(built.run)
    videos = page.find("video")
    assert len(videos) == store.num_episodes // 2 == 2
    for v in videos:
        assert is_mp4(data_payload(v.attrs["src"], "video/mp4"))
        assert data_payload(v.attrs["poster"], "image/png").startswith(b"\x89PNG\r\n\x1a\n")
    table = page.by_id("metrics-table")
    assert table is not None and table.tag == "table"
    text = text_of(table)
    assert "sort_cubes" in text and "overall" in text and "0.45" in text and "[0.25, 0.75]" in text
    ranks = page.by_id("rank-table")
    assert ranks is not None and "0.987" in text_of(ranks) and "—" in text_of(ranks)  # MMRV missing → dash
    charts = page.by_class("chart")
    assert len(charts) == 3  # success scatter, single-step curves, closed-loop divergence
    for img in page.find("img"):
        assert data_payload(img.attrs["src"], "image/png").startswith(b"\x89PNG")


def test_each_pair_shows_rows_columns_verdicts_and_the_hallucination_mark(built: Built) -> None:
    page = parse(built.report.read_text(encoding="utf-8"))
    articles = page.find("article")
    assert [a.attrs["data-pair"] for a in articles] == list(built.hallucinations)
    for i, article in enumerate(articles):
        pair = article.attrs["data-pair"]
        inside = [e for e in page.elements if f"pair-{i}" in e.ids]
        labels = [text_of(e) for e in inside if e.tag == "div" and "rowlabels" in e.classes]
        assert labels == [" ".join([*VIEWS, "control video Γ"])]
        heads = [text_of(e) for e in inside if "colheads" in e.classes]
        assert heads == ["real imagined"]
        tables = [e for e in inside if e.tag == "table" and "outcomes" in e.classes]
        assert len(tables) == 1
        verdicts = text_of(tables[0])
        assert "sim_checker" in verdicts and "vision_fake" in verdicts
        assert ("✓" in verdicts) or ("✗" in verdicts)
        marks = [e for e in inside if e.tag == "button" and "hmark" in e.classes]
        t_h = built.hallucinations[pair]
        if t_h is None:
            assert marks == []
        else:
            assert [int(m.attrs["data-seek"]) for m in marks] == [t_h]
            links = [e for e in inside if e.tag == "a" and e.attrs.get("data-seek") == str(t_h)]
            assert any(f"frame {t_h}" in text_of(a) and f"{t_h / 10:.2f} s" in text_of(a) for a in links)
    assert any(t is not None for t in built.hallucinations.values())


def test_tile_video_holds_real_left_imagined_right_and_the_control_row(built: Built, tmp_path: Path) -> None:
    page = parse(built.report.read_text(encoding="utf-8"))
    store = EpisodeStore(built.run)
    imagined, real = store.load(0), store.load(1)
    assert (imagined.origin, real.origin) == ("imagined", "real")
    mp4 = tmp_path / "tile.mp4"
    mp4.write_bytes(data_payload(page.find("video")[0].attrs["src"], "video/mp4"))
    frames = read_video(mp4)
    T, h = real.length, 128
    assert frames.shape == (T, 4 * h + 3 * GAP, 2 * h + GAP, 3)

    def cell(t: int, row: int, col: int) -> np.ndarray:
        y, x = row * (h + GAP), col * (h + GAP)
        return frames[t, y : y + h, x : x + h].astype(np.float64)

    for row, view in enumerate(VIEWS):  # H.264 at crf 23: a few levels of error, far below the branch gap
        for col, ep in ((0, real), (1, imagined)):
            err = np.abs(cell(T - 1, row, col) - ep.images[view][-1]).mean()
            other = (imagined if ep is real else real).images[view][-1]
            assert err < 6.0, (view, col, err)
            assert err < np.abs(cell(T - 1, row, col) - other).mean(), (view, col)
    gamma = ControlVideo.from_rig(RigConfig.load(SIM), SPEC)
    for col, ep in ((0, real), (1, imagined)):
        expected = control_frames(ep, gamma)
        assert np.abs(cell(T - 1, 3, col) - expected[-1]).mean() < 6.0
    assert cell(0, 3, 0).mean() < 3.0  # the start frame has no control frame


def test_control_frames_use_each_rounds_actions_and_start_state() -> None:
    """Frame j of round r is Γ of the command stored with frame j − 1, from the state at the round's start."""
    rig = RigConfig.load(SIM)
    K = 4
    from pilworld.types import ChunkSpec

    gamma = ControlVideo.from_rig(rig, ChunkSpec(frames=K, stride=3, rounds=2))
    rng = np.random.default_rng(0)
    T = 1 + 2 * K
    home = np.array([0, -1.2, 1.6, -1.9, -1.57, 0, 1, 0, -1.2, 1.6, -1.9, -1.57, 0, 1], dtype=np.float32)
    state = home + rng.normal(0, 0.05, (T, 14)).astype(np.float32)
    action = home + rng.normal(0, 0.2, (T, 14)).astype(np.float32)
    action[:, [6, 13]] = rng.uniform(0, 1, (T, 2))
    images = {v: np.zeros((T, 128, 128, 3), np.uint8) for v in VIEWS}
    rounds = np.array([0] + [0] * K + [1] * K, dtype=np.int64)
    ep = Episode(images=images, state=state, action=action, task="t", round_index=rounds)
    got = control_frames(ep, gamma)
    assert got.shape == (T, 128, 128, 3) and not got[0].any()
    r0 = gamma.render_stride_aligned(action[0:K][None].astype(np.float64), state[0][None])[0]
    r1 = gamma.render_stride_aligned(action[K : 2 * K][None].astype(np.float64), state[K][None])[0]
    np.testing.assert_array_equal(got[1 : K + 1], r0)
    np.testing.assert_array_equal(got[K + 1 :], r1)
    assert got[1:].any()


def test_report_is_self_contained(built: Built) -> None:
    html = built.report.read_text(encoding="utf-8")
    assert re.search(r"https?:", html, re.IGNORECASE) is None
    assert re.search(r"(?<![a-z-])(src|href|poster)=\"(?!data:|#)", html) is None  # only data: URIs and anchors
    assert "<link" not in html and "<iframe" not in html and "@import" not in html
    assert re.search(r"<script[^>]*\bsrc=", html) is None
    assert re.search(r"url\((?!data:)", html) is None


def test_max_pairs_leaves_videos_out_and_says_so(
    paired_dir: tuple[Path, dict[str, int | None]], tmp_path: Path
) -> None:
    run, _ = paired_dir
    path = build_report(run, tmp_path / "capped.html", max_pairs=1)
    page = parse(path.read_text(encoding="utf-8"))
    assert len(page.find("video")) == 1 and len(page.find("article")) == 2
    note = page.by_id("pairs-note")
    assert note is not None and note.attrs["data-left-out"] == "1" and "1 left out" in text_of(note)
    assert len(page.by_class("novideo")) == 1
    with pytest.raises(ValueError, match="max_pairs"):
        build_report(run, tmp_path / "bad.html", max_pairs=-1)


def test_without_metrics_json_the_page_says_so(paired_dir: tuple[Path, dict[str, int | None]], tmp_path: Path) -> None:
    run, _ = paired_dir
    copy = tmp_path / "run"
    shutil.copytree(run, copy, ignore=shutil.ignore_patterns("report.html", "metrics.json"))
    page = parse(build_report(copy, max_pairs=0).read_text(encoding="utf-8"))
    assert (copy / "report.html").is_file()
    assert page.by_id("metrics-table") is None
    missing = page.by_id("metrics-missing")
    assert missing is not None and "metrics.json not found" in text_of(missing)
    assert len(page.by_class("chart")) == 1  # only the closed-loop curve, computed from the run itself
    (copy / "metrics.json").write_text("[1, 2]")
    page = parse(build_report(copy, max_pairs=0).read_text(encoding="utf-8"))
    missing = page.by_id("metrics-missing")
    assert missing is not None and "expected a JSON object" in text_of(missing)


def test_not_a_paired_run_is_refused(tmp_path: Path) -> None:
    with pytest.raises(DatasetError, match="not a LeRobot dataset"):
        build_report(tmp_path)
    with pytest.raises(FileNotFoundError, match="RUN_DIR"):
        build_report(tmp_path / "nothing")


def test_cli_writes_the_report_and_prints_json(
    paired_dir: tuple[Path, dict[str, int | None]], tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    run, _ = paired_dir
    parser = argparse.ArgumentParser(prog="pilworld")
    report_cli.register(parser.add_subparsers(dest="command"))
    out = tmp_path / "r.html"
    args = parser.parse_args(["report", str(run), "--out", str(out), "--max-pairs", "0", "--json"])
    assert args.handler(args) == 0
    stats = json.loads(capsys.readouterr().out.strip().splitlines()[-1])
    assert stats["path"] == str(out) and stats["videos"] == 0 and stats["bytes"] == out.stat().st_size
    args = parser.parse_args(["report", str(run), "--max-pairs", "-1"])
    with pytest.raises(ValueError, match="--max-pairs"):
        args.handler(args)


def test_report_reads_the_metrics_package_output(
    paired_dir: tuple[Path, dict[str, int | None]], tmp_path: Path
) -> None:
    """metrics.json as pilworld.metrics writes it (one setting: Pearson undefined, with its reason)."""
    run, _ = paired_dir
    copy = tmp_path / "run"
    shutil.copytree(run, copy, ignore=shutil.ignore_patterns("report.html", "metrics.json"))
    written = write_metrics(copy, bootstrap=50, lpips=False)
    page = parse(build_report(copy, max_pairs=0).read_text(encoding="utf-8"))
    table, ranks = page.by_id("metrics-table"), page.by_id("rank-table")
    assert table is not None and ranks is not None
    overall = written["overall"]
    assert f"{overall['sr_imag']:.2f}" in text_of(table)
    if overall.get("pearson") is None:
        cells = [e for e in page.elements if e.tag == "td" and "rank-table" in e.ids]
        assert any(e.attrs.get("title") == overall["pearson_reason"] for e in cells)
    titles = [text_of(e) for e in page.by_class("chart")]
    assert len(titles) == 3, titles  # scatter (one point), single-step curves, closed-loop curves
