"""The report in headless Chromium: it renders, its videos decode, the hallucination marker seeks.

Skipped when no Chromium is installed (``scripts/install-chromium.sh`` installs Debian's ``chromium``).
"""

from __future__ import annotations

import re
from pathlib import Path

import cv2
import numpy as np
import pytest

from pilworld.report.chromium import dump_dom, find_chromium, screenshot
from tests.pilworld.report.conftest import Built
from tests.pilworld.report.page_parse import data_payload, is_mp4, parse

pytestmark = pytest.mark.skipif(
    find_chromium() is None,
    reason="no Chromium/Chrome binary found (install it with scripts/install-chromium.sh, or set PILWORLD_CHROMIUM)",
)

# Clicks the pair's hallucination marker once its video is loaded and records where the video seeked to.
PROBE = """<script>
(function () {
  var pair = document.getElementById('pair-PAIR_INDEX'), video = pair.querySelector('video');
  function go() {
    video.addEventListener('seeked', function () {
      document.body.setAttribute('data-seeked-time', String(video.currentTime));
    });
    pair.querySelector('button.hmark').click();
  }
  if (video.readyState >= 1) go(); else video.addEventListener('loadedmetadata', go);
})();
</script></body>"""


def test_screenshot_shows_the_page(built: Built, tmp_path: Path) -> None:
    png = screenshot(built.report, tmp_path / "report.png", size=(1200, 1800))
    image = cv2.imread(str(png), cv2.IMREAD_COLOR)
    assert image is not None, f"{png} is not an image"
    assert image.shape == (1800, 1200, 3)
    colours = np.unique(image.reshape(-1, 3), axis=0)
    assert len(colours) > 200, f"only {len(colours)} distinct colours: blank or unstyled page"
    assert (image.mean(axis=2) < 128).mean() > 0.01  # text, charts and video frames, not only background


def test_videos_decode_and_the_metrics_table_is_in_the_dom(built: Built) -> None:
    dom = dump_dom(built.report)
    page = parse(dom)
    body = page.find("body")[0]
    assert body.attrs.get("data-js") == "ran"
    videos = page.find("video")
    pairs = len(built.hallucinations)
    assert len(videos) == pairs == 2
    for v in videos:
        assert is_mp4(data_payload(v.attrs["src"], "video/mp4"))
        assert "data-error" not in v.attrs, v.attrs.get("data-error")
        # Set by the page's script on loadedmetadata: Chromium decoded the H.264 stream.
        assert re.fullmatch(r"\d+x\d+", v.attrs.get("data-decoded", "")), "video metadata never loaded"
    assert body.attrs.get("data-videos-ready") == str(pairs)
    table = page.by_id("metrics-table")
    assert table is not None and table.tag == "table"


def test_hallucination_marker_seeks_the_video(built: Built, tmp_path: Path) -> None:
    index, t_h = next((i, t) for i, t in enumerate(built.hallucinations.values()) if t is not None)
    probe = PROBE.replace("PAIR_INDEX", str(index))
    page = tmp_path / "probe.html"
    page.write_text(built.report.read_text(encoding="utf-8").replace("</body>", probe), encoding="utf-8")
    body = parse(dump_dom(page)).find("body")[0]
    seeked = body.attrs.get("data-seeked-time")
    assert seeked is not None, "the marker click did not seek the video"
    assert int(float(seeked) * 10) == t_h  # 10 fps: the video shows frame t_h
