"""Killing ``pilworld annotate serve`` (SIGKILL) loses no label whose PUT was answered."""

from __future__ import annotations

import http.client
import os
import re
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path
from typing import IO

from pilworld.annotate.store import AnnotationStore
from pilworld.judges.hallucination_checks import CATEGORIES
from tests.pilworld.annotate.client import Client

URL = re.compile(r" at (http://127\.0\.0\.1:\d+) ")
LOGIN = re.compile(r"Judge (\d+): (http://\S+/login\?token=(\S+))")


def _start(run: Path, *extra: str) -> tuple[subprocess.Popen[str], str, dict[int, str]]:
    env = {**os.environ, "PYTHONUNBUFFERED": "1"}
    cmd = [sys.executable, "-m", "pilworld.cli.main", "annotate", "serve", str(run), "--port", "0", *extra]
    proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True, env=env)
    assert proc.stdout is not None
    url, tokens, lines = "", {}, []
    deadline = time.monotonic() + 60
    for line in _lines(proc.stdout, deadline):
        lines.append(line)
        if m := URL.search(line):
            url = m[1]
        if m := LOGIN.search(line):
            tokens[int(m[1])] = m[3]
        if line.startswith("Give each judge"):
            break
    assert url, "".join(lines)
    return proc, url, tokens


def _lines(stream: IO[str], deadline: float) -> list[str]:
    out = []
    while time.monotonic() < deadline:
        line = stream.readline()
        if not line:
            break
        out.append(line)
        if line.startswith("Give each judge"):
            break
    return out


def test_sigkill_loses_no_acknowledged_label(run: Path) -> None:
    proc, url, tokens = _start(run, "--judges", "2")
    assert sorted(tokens) == [1, 2]
    acked: dict[tuple[int, str], dict[str, object]] = {}  # (judge, item) → last body answered with 200
    # the PUT in flight when the server died may or may not have been committed: either value is right
    pending: dict[tuple[int, str], dict[str, object]] = {}
    stop = threading.Event()
    try:
        clients = {j: Client(url, t) for j, t in tokens.items()}
        queues = {j: c.queue() for j, c in clients.items()}

        def hammer(judge: int) -> None:
            """Label and revise this judge's items until the server dies; remember what was acknowledged."""
            n = 0
            while not stop.is_set():
                item = queues[judge][n % len(queues[judge])]
                body = {"success": n % 3 == 0, "first_hallucination_frame": n % 16, "category": CATEGORIES[n % 5]}
                pending[(judge, item)] = body
                try:
                    r = clients[judge].put_json(f"/api/items/{item}/label", body)
                except (OSError, http.client.HTTPException):  # the server died mid-request
                    return
                if r.status == 200:
                    acked[(judge, item)] = body
                del pending[(judge, item)]
                n += 1

        threads = [threading.Thread(target=hammer, args=(j,)) for j in tokens]
        for t in threads:
            t.start()
        deadline = time.monotonic() + 20
        while len(acked) < 8 and time.monotonic() < deadline:  # every item of both judges written at least once
            time.sleep(0.05)
        time.sleep(0.3)
        proc.send_signal(signal.SIGKILL)
        proc.wait(timeout=10)
        stop.set()
        for t in threads:
            t.join(timeout=30)
    finally:
        stop.set()
        if proc.poll() is None:
            proc.kill()
            proc.wait()
        if proc.stdout is not None:
            proc.stdout.close()
    assert len(acked) == 8 and len(pending) <= 2

    proc2, url2, fresh = _start(run, "--judges", "2")
    try:
        assert fresh == {}  # the same judges and tokens
        for (judge, item), body in acked.items():
            r = Client(url2, tokens[judge]).get(f"/api/items/{item}")
            assert r.status == 200 and r.json()["label"] in (body, pending.get((judge, item))), (judge, item)
        assert Client(url2, tokens[1]).get("/api/me").json()["done"] == 4
    finally:
        proc2.send_signal(signal.SIGINT)  # Ctrl-C: stops and exports
        try:
            out, _ = proc2.communicate(timeout=120)
        except subprocess.TimeoutExpired:
            proc2.kill()
            out, _ = proc2.communicate()
            raise AssertionError(f"the server did not stop within 120 s of Ctrl-C; it printed:\n{out}") from None
    assert proc2.returncode == 0, out
    assert "exported labels" in out and "human_1 4, human_2 4" in out
    assert AnnotationStore(run).counts() == {1: 4, 2: 4}
