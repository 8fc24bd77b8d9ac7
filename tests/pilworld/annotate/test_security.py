"""Security of the annotation API: authentication, isolation between judges, validation, blinding."""

from __future__ import annotations

import json
import re
from pathlib import Path

import av
import numpy as np
import pytest

from pilworld.annotate.server import AnnotationServer
from pilworld.judges.hallucination_checks import CATEGORIES
from tests.pilworld.annotate.client import Client, Response
from tests.pilworld.annotate.conftest import CHECKPOINTS

GOOD = {"success": True, "first_hallucination_frame": 3, "category": CATEGORIES[1]}


def _is_401_json(r: Response) -> bool:
    return r.status == 401 and r.headers["content-type"] == "application/json" and "error" in r.json()


def test_no_token_is_401_everywhere(server: AnnotationServer, judge1: Client) -> None:
    item = judge1.queue()[0]
    anon = Client(server.url)
    for path in ["/", "/index.html", "/api/me", "/api/queue", f"/api/items/{item}", f"/media/{item}/cam_high.mp4",
                 "/static/app.js", "/nowhere", "/login", "/login?token="]:  # fmt: skip
        assert _is_401_json(anon.get(path)), path
    assert _is_401_json(anon.put_json(f"/api/items/{item}/label", GOOD))
    assert judge1.get(f"/api/items/{item}").json()["label"] is None  # nothing was written


def test_bad_tokens_are_401(server: AnnotationServer, judge1: Client) -> None:
    item = judge1.queue()[0]
    wrong = server.tokens[1][:-1] + ("A" if server.tokens[1][-1] != "A" else "B")
    for client in (Client(server.url, wrong), Client(server.url, cookie=wrong), Client(server.url, "")):
        assert _is_401_json(client.get("/api/me"))
        assert _is_401_json(client.get(f"/media/{item}/cam_high.mp4"))
        assert _is_401_json(client.put_json(f"/api/items/{item}/label", GOOD))
    r = Client(server.url).get(f"/login?token={wrong}")
    assert _is_401_json(r) and "set-cookie" not in r.headers
    # a stored hash is not a token either
    assert _is_401_json(Client(server.url, server.store.derive("x")).get("/api/me"))


def test_a_judge_cannot_read_or_write_another_judges_items(judge1: Client, judge2: Client) -> None:
    mine, theirs = judge1.queue(), judge2.queue()
    assert judge2.label(theirs[0], False, 5, CATEGORIES[0]).status == 200
    for item in theirs:
        assert judge1.get(f"/api/items/{item}").status == 404
        assert judge1.get(f"/media/{item}/cam_high.mp4").status == 404
        assert judge1.label(item, True).status == 404
    # judge 2's label is untouched, judge 1 sees none of it anywhere
    assert judge2.get(f"/api/items/{theirs[0]}").json()["label"] == {
        "success": False,
        "first_hallucination_frame": 5,
        "category": CATEGORIES[0],
    }
    assert judge1.get("/api/me").json()["done"] == 0
    assert not any(i["done"] for i in judge1.get("/api/queue").json()["items"])
    assert all(judge1.get(f"/api/items/{i}").json()["label"] is None for i in mine)
    for bogus in ["0" * 16, "../../etc/passwd", "%2e%2e", mine[0].upper(), mine[0][:15]]:
        assert judge1.get(f"/api/items/{bogus}").status == 404
        assert judge1.label(bogus, True).status == 404


BAD_BODIES: list[tuple[object, str]] = [
    ({"success": True, "first_hallucination_frame": 16, "category": CATEGORIES[0]}, "first_hallucination_frame"),
    ({"success": True, "first_hallucination_frame": -1, "category": CATEGORIES[0]}, "first_hallucination_frame"),
    ({"success": True, "first_hallucination_frame": 2.0, "category": CATEGORIES[0]}, "first_hallucination_frame"),
    ({"success": True, "first_hallucination_frame": "2", "category": CATEGORIES[0]}, "first_hallucination_frame"),
    ({"success": True, "first_hallucination_frame": True, "category": CATEGORIES[0]}, "first_hallucination_frame"),
    ({"success": True, "first_hallucination_frame": 2, "category": "ghosts"}, "category"),
    ({"success": True, "first_hallucination_frame": 2, "category": None}, "category"),
    ({"success": True, "first_hallucination_frame": None, "category": CATEGORIES[0]}, "category"),
    ({"success": "yes", "first_hallucination_frame": None, "category": None}, "success"),
    ({"success": 1, "first_hallucination_frame": None, "category": None}, "success"),
    ({"first_hallucination_frame": None, "category": None}, "success"),
    ({"success": True, "origin": "real"}, "origin"),
    ([True, None, None], "body"),
    ("success", "body"),
]


@pytest.mark.parametrize(("body", "field"), BAD_BODIES)
def test_invalid_labels_are_400_naming_the_field(judge1: Client, body: object, field: str) -> None:
    item = judge1.queue()[0]
    r = judge1.put_json(f"/api/items/{item}/label", body)
    assert r.status == 400 and r.json()["field"] == field and r.json()["error"].startswith(field)
    assert judge1.get(f"/api/items/{item}").json()["label"] is None


def test_malformed_and_oversized_bodies_are_400(judge1: Client) -> None:
    path = f"/api/items/{judge1.queue()[0]}/label"
    assert judge1.request("PUT", path, b"{not json").json()["field"] == "body"
    assert judge1.request("PUT", path, b"\xff\xfe").json()["field"] == "body"
    big = json.dumps({"success": True, "pad": "x" * 5000}).encode()
    r = judge1.request("PUT", path, big)
    assert r.status == 400 and r.json()["field"] == "body" and "4096" in r.json()["error"]
    assert judge1.get("/api/me").json()["done"] == 0


def test_a_full_walk_reveals_nothing(server: AnnotationServer, judge1: Client, run: Path) -> None:
    """Every body a judge receives — page, JSON, MP4 bytes — is free of origin, checkpoint, run and index hints."""
    judge1.get("/")
    judge1.get("/api/me")
    for n, item in enumerate(judge1.queue()):
        data = judge1.get(f"/api/items/{item}").json()
        for url in data["media"].values():
            assert judge1.get(url).status == 200
            judge1.get(url, {"Range": "bytes=0-1023"})
        judge1.label(item, n % 2 == 0, n + 1, CATEGORIES[n % len(CATEGORIES)])
        judge1.get(f"/api/items/{item}")
    judge1.get("/api/queue")
    judge1.get("/api/me")
    forbidden = [b"real", b"imagined", b"origin", b"checkpoint", b"scripted", b"seed", b"pair", b"episode",
                 b"subtask", b"sort_cubes", b"sim_checker", b"annotate_cache", b"Lavf", b"x264",
                 str(run).encode(), run.name.encode(), *(c.encode() for c in CHECKPOINTS)]  # fmt: skip
    walked = 0
    for path, r in judge1.seen:
        blob = r.body + json.dumps(r.headers).encode()
        lower = blob.lower()
        for word in forbidden:
            assert word.lower() not in lower, (path, word)
        if r.headers.get("content-type") == "application/json":
            text = r.body.decode()
            assert not re.search(r'"(episode|index|origin|checkpoint|seed|pair|path)[a-z_]*"', text), path
        walked += 1
    assert walked >= 4 * (3 * 2 + 3) + 4


def test_media_files_carry_no_metadata_and_the_true_frames(
    server: AnnotationServer, judge1: Client, tmp_path: Path
) -> None:
    item = judge1.queue()[0]
    path = tmp_path / "v.mp4"
    path.write_bytes(judge1.get(f"/media/{item}/cam_left_wrist.mp4").body)
    with av.open(str(path)) as c:
        assert set(c.metadata) <= {"major_brand", "minor_version", "compatible_brands"}
        stream = c.streams.video[0]
        assert not {"title", "comment", "encoder", "description"} & set(stream.metadata)
        assert (stream.codec_context.width, stream.codec_context.height) == (128, 128)  # the rig's size
        frames = np.stack([f.to_ndarray(format="rgb24") for f in c.decode(stream)])
    episode = server.app.catalog.episode_of(1, item)
    assert episode is not None
    truth = server.app.dataset.frames(episode, "cam_left_wrist")
    assert frames.shape == truth.shape == (16, 128, 128, 3)
    assert np.abs(frames.astype(np.int16) - truth).mean() < 3.0  # H.264 at CRF 20: the same pictures
