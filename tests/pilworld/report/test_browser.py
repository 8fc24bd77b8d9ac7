"""The report in headless Chromium: it renders, its videos decode, the hallucination marker seeks.

Every check waits for the page to reach a state (scripts ran, each video decoded, the video seeked), not
for a budget of time, so the tests hold on a loaded machine (``test_browser_under_load.py`` runs them with
every core busy). Skipped when no Chromium is installed (``scripts/install-chromium.sh`` installs Debian's
``chromium``).
"""

from __future__ import annotations

import re
from collections.abc import Iterator
from pathlib import Path

import cv2
import numpy as np
import pytest
from playwright.sync_api import Browser, Page

from pilworld.report.chromium import find_chromium
from tests.pilworld.browser import chromium, wait_for
from tests.pilworld.report.conftest import Built
from tests.pilworld.report.page_parse import data_payload, is_mp4, parse

pytestmark = pytest.mark.skipif(
    find_chromium() is None,
    reason="no Chromium/Chrome binary found (install it with scripts/install-chromium.sh, or set PILWORLD_CHROMIUM)",
)

PAIRS = 2  # the conftest's run: 2 pairs, one video each
VIDEOS_READY = f"document.body.getAttribute('data-videos-ready') === '{PAIRS}'"


@pytest.fixture(scope="module")
def browser() -> Iterator[Browser]:
    with chromium() as b:
        yield b


@pytest.fixture
def page(browser: Browser, built: Built) -> Iterator[Page]:
    """The report opened at 1200×1800, its scripts run and every video's metadata decoded."""
    p = browser.new_page(viewport={"width": 1200, "height": 1800})
    try:
        p.goto(built.report.resolve().as_uri())
        wait_for(p, "document.body.getAttribute('data-js') === 'ran'", "the page's script to run")
        wait_for(p, VIDEOS_READY, f"all {PAIRS} videos to decode")
        yield p
    finally:
        p.close()


def test_screenshot_shows_the_page(page: Page, tmp_path: Path) -> None:
    png = tmp_path / "report.png"
    page.screenshot(path=str(png))
    image = cv2.imread(str(png), cv2.IMREAD_COLOR)
    assert image is not None, f"{png} is not an image"
    assert image.shape == (1800, 1200, 3)
    colours = np.unique(image.reshape(-1, 3), axis=0)
    assert len(colours) > 200, f"only {len(colours)} distinct colours: blank or unstyled page"
    assert (image.mean(axis=2) < 128).mean() > 0.01  # text, charts and video frames, not only background


def test_videos_decode_and_the_metrics_table_is_in_the_dom(page: Page, built: Built) -> None:
    dom = parse(page.content())
    body = dom.find("body")[0]
    assert body.attrs.get("data-js") == "ran"
    videos = dom.find("video")
    assert len(videos) == len(built.hallucinations) == PAIRS
    for v in videos:
        assert is_mp4(data_payload(v.attrs["src"], "video/mp4"))
        assert "data-error" not in v.attrs, v.attrs.get("data-error")
        # Set by the page's script on loadedmetadata: Chromium decoded the H.264 stream.
        assert re.fullmatch(r"\d+x\d+", v.attrs.get("data-decoded", "")), "video metadata never loaded"
    table = dom.by_id("metrics-table")
    assert table is not None and table.tag == "table"


def test_hallucination_marker_seeks_the_video(page: Page, built: Built) -> None:
    index, t_h = next((i, t) for i, t in enumerate(built.hallucinations.values()) if t is not None)
    # Record where the video seeks to, then click the pair's marker.
    page.evaluate(
        """(index) => {
            const pair = document.getElementById('pair-' + index), video = pair.querySelector('video');
            const record = () => document.body.setAttribute('data-seeked-time', String(video.currentTime));
            video.addEventListener('seeked', record);
            pair.querySelector('button.hmark').click();
        }""",
        index,
    )
    seeked = wait_for(page, "document.body.getAttribute('data-seeked-time')", "the marker click to seek the video")
    assert int(float(seeked) * 10) == t_h  # 10 fps: the video shows frame t_h
