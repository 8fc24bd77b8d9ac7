"""The HTTP API as the judging page uses it (docs/annotate.md): login, progress, queue, items, labels, media."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from pilworld.annotate.server import SECURITY_HEADERS, AnnotationServer, parse_range
from pilworld.judges.hallucination_checks import CATEGORIES
from tests.pilworld.annotate.client import Client


def test_login_sets_a_strict_cookie_and_redirects(server: AnnotationServer) -> None:
    anon = Client(server.url)
    r = anon.get(f"/login?token={server.tokens[2]}")
    assert r.status == 303 and r.headers["location"] == "/"
    cookie = r.headers["set-cookie"]
    assert cookie.startswith(f"pilworld_judge={server.tokens[2]};")
    assert "HttpOnly" in cookie and "SameSite=Strict" in cookie
    me = Client(server.url, cookie=server.tokens[2]).get("/api/me")
    assert me.status == 200 and me.json() == {"judge": "Judge 2", "total": 4, "done": 0}


def test_page_is_served_as_html(judge1: Client) -> None:
    r = judge1.get("/")
    assert r.status == 200 and r.headers["content-type"].startswith("text/html")
    assert b"<html" in r.body.lower()


def test_item_and_label_round_trip(judge1: Client) -> None:
    queue = judge1.queue()
    assert len(queue) == 4 and len(set(queue)) == 4
    item = judge1.get(f"/api/items/{queue[1]}").json()
    assert set(item) == {"id", "num_frames", "fps", "instruction", "views", "media", "categories", "label"}
    assert item["id"] == queue[1] and item["num_frames"] == 16 and item["fps"] == 10
    assert item["views"] == ["cam_high", "cam_left_wrist", "cam_right_wrist"]
    assert item["media"] == {v: f"/media/{queue[1]}/{v}.mp4" for v in item["views"]}
    assert item["categories"] == list(CATEGORIES) and item["label"] is None
    assert item["instruction"].strip()

    r = judge1.label(queue[1], True, 15, CATEGORIES[0])
    assert r.status == 200 and r.json() == {"ok": True, "done": 1, "total": 4}
    r = judge1.label(queue[1], False)  # revise: same item, no double count
    assert r.json() == {"ok": True, "done": 1, "total": 4}
    assert judge1.get(f"/api/items/{queue[1]}").json()["label"] == {
        "success": False,
        "first_hallucination_frame": None,
        "category": None,
    }
    assert [i["done"] for i in judge1.get("/api/queue").json()["items"]] == [False, True, False, False]
    assert judge1.get("/api/me").json()["done"] == 1


def test_omitted_frame_and_category_mean_none(judge1: Client) -> None:
    item = judge1.queue()[0]
    assert judge1.put_json(f"/api/items/{item}/label", {"success": True}).status == 200
    assert judge1.get(f"/api/items/{item}").json()["label"]["first_hallucination_frame"] is None


def test_orders_differ_between_judges_and_survive_a_restart(run: Path) -> None:
    srv = AnnotationServer(run, judges=2).start()
    try:
        a, b = Client(srv.url, srv.tokens[1]), Client(srv.url, srv.tokens[2])
        qa, qb = a.queue(), b.queue()
        first = {k: a.get(f"/api/items/{k}").json()["instruction"] for k in qa}
        tokens = srv.tokens
    finally:
        srv.stop()
    assert set(qa).isdisjoint(qb)  # ids are per judge
    again = AnnotationServer(run, judges=2).start()
    try:
        assert again.tokens == {}
        assert Client(again.url, tokens[1]).queue() == qa
        assert Client(again.url, tokens[2]).queue() == qb
        assert len(first) == 4
    finally:
        again.stop()


def test_media_is_mp4_with_ranges(judge1: Client) -> None:
    item = judge1.queue()[0]
    full = judge1.get(f"/media/{item}/cam_high.mp4")
    assert full.status == 200 and full.headers["content-type"] == "video/mp4"
    assert full.headers["accept-ranges"] == "bytes" and full.body[4:8] == b"ftyp"
    size = len(full.body)
    part = judge1.get(f"/media/{item}/cam_high.mp4", {"Range": "bytes=10-99"})
    assert part.status == 206 and part.body == full.body[10:100]
    assert part.headers["content-range"] == f"bytes 10-99/{size}"
    tail = judge1.get(f"/media/{item}/cam_high.mp4", {"Range": "bytes=-20"})
    assert tail.status == 206 and tail.body == full.body[-20:]
    opened = judge1.get(f"/media/{item}/cam_high.mp4", {"Range": "bytes=0-"})
    assert opened.status == 206 and opened.body == full.body
    bad = judge1.get(f"/media/{item}/cam_high.mp4", {"Range": f"bytes={size}-"})
    assert bad.status == 416 and bad.headers["content-range"] == f"bytes */{size}"
    assert judge1.get(f"/media/{item}/cam_nope.mp4").status == 404


def test_parse_range() -> None:
    assert parse_range("bytes=0-0", 10) == (0, 0)
    assert parse_range("bytes=5-100", 10) == (5, 9)
    assert parse_range("bytes=-3", 10) == (7, 9)
    assert parse_range("bytes=0-1,4-5", 10) is None  # several ranges: the whole file
    assert parse_range("items=0-1", 10) is None


@pytest.mark.parametrize("method", ["POST", "DELETE", "PATCH", "HEAD", "OPTIONS", "BREW"])
def test_other_methods_are_405(judge1: Client, method: str) -> None:
    r = judge1.request(method, "/api/me")
    assert r.status == 405
    if method != "HEAD":
        assert "error" in json.loads(r.body)


def test_every_response_has_the_security_headers(judge1: Client, server: AnnotationServer) -> None:
    item = judge1.queue()[0]
    judge1.get(f"/api/items/{item}")
    judge1.get(f"/media/{item}/cam_high.mp4")
    judge1.label(item, True, 99, None)  # 400
    judge1.get("/api/items/0123456789abcdef")  # 404
    judge1.request("POST", "/")  # 405
    Client(server.url).get("/api/me")  # 401 (not recorded by judge1)
    Client(server.url).get(f"/login?token={server.tokens[1]}")  # 303
    for path, r in judge1.seen:
        for k, v in SECURITY_HEADERS.items():
            assert r.headers.get(k.lower()) == v, (path, r.status, k)


def test_not_a_dataset_and_remote_hosts_are_refused(tmp_path: Path, run: Path) -> None:
    with pytest.raises(ValueError, match="not a LeRobot dataset"):
        AnnotationServer(tmp_path, judges=1)
    assert not (tmp_path / "annotations.sqlite").exists()
    with pytest.raises(ValueError, match="--allow-remote"):
        AnnotationServer(run, judges=1, host="0.0.0.0")
    with pytest.raises(ValueError, match="--judges"):
        AnnotationServer(run)
