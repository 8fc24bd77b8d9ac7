"""Every way a policy server can fail a paired run: one line naming the checkpoint and what happened,
exit status 1, no traceback, the stored branches intact, and a rerun against a good server resuming.

Each case runs ``pilworld paired run`` in process against :class:`FaultyServer` (a real websocket server
on loopback) on the simulated rig, one round per branch (one inference request per branch). The
branches run imagined, real, imagined, real: a fault after two answered requests loses the second
pair. A fault at connection time (nothing listening, closed before the metadata) hits a run extended
from one subtask to two, so a stored pair exists there too.
"""

from __future__ import annotations

import json
import shutil
from collections.abc import Iterator
from pathlib import Path

import pytest

from pilworld.cli.main import main
from pilworld.data.reader import EpisodeStore
from pilworld.paired.policy_metadata import METADATA_FILE
from pilworld.policies.registry import CONNECT_TIMEOUT_ENV, REPLY_TIMEOUT_ENV
from tests.pilworld.cli.faulty_server import FaultyServer, free_port

SIM = "configs/rig/sim_dual_ur5e.yaml"
CKPT = "scripted_step_30k"
REPLY_TIMEOUT_S = 1.5  # long enough for the scripted policy on a busy machine, short for the stall case

# mode of the server, requests answered before it misbehaves, the kind the error line must name
CASES = {
    "nothing listening": ("down", None, "unreachable"),
    "closed before metadata": ("close_before_metadata", None, "handshake failed"),
    "exception reply": ("exception", 2, "server error"),
    "timeout": ("stall", 2, "timeout"),
    "wrong shape": ("wrong_shape", 2, "invalid actions"),
    "nan actions": ("nan", 2, "invalid actions"),
}


@pytest.fixture(scope="module")
def server() -> Iterator[FaultyServer]:
    with FaultyServer(SIM, CKPT, free_port()) as s:
        yield s


@pytest.fixture(autouse=True)
def _short_timeouts(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv(CONNECT_TIMEOUT_ENV, "5")
    monkeypatch.setenv(REPLY_TIMEOUT_ENV, str(REPLY_TIMEOUT_S))
    monkeypatch.delenv("PILWORLD_DEBUG", raising=False)


def _run(out: Path, url: str, subtasks: int) -> list[str]:
    return [
        "paired", "run", "--rig", SIM, "--task", "sort_cubes", "--checkpoints", url,
        "--subtasks", str(subtasks), "--rounds", "1", "--out", str(out), "--json",
    ]  # fmt: skip


@pytest.fixture(scope="module")
def one_pair(server: FaultyServer, tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A run folder with the first pair stored (both branches), made once and copied per case."""
    server.set_mode("good")
    out = tmp_path_factory.mktemp("faults") / "one_pair"
    with pytest.MonkeyPatch.context() as mp:
        mp.setenv(REPLY_TIMEOUT_ENV, "30")
        assert main(_run(out, server.url, 1)) == 0
    return out


def _pairs(out: Path) -> list[tuple[str, str]]:
    store = EpisodeStore(out)
    eps = [store.load(i) for i in range(store.num_episodes)]  # every stored episode still loads
    return [(str(e.extra["pair"]), e.origin) for e in eps]


@pytest.mark.parametrize("case", list(CASES))
def test_a_policy_failure_is_one_line_and_the_run_resumes(
    case: str, server: FaultyServer, one_pair: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    mode, fail_after, kind = CASES[case]
    out = tmp_path / "run"
    if fail_after is None:  # a connection-time fault: extend the stored one-pair run to two subtasks
        shutil.copytree(one_pair, out)
    capsys.readouterr()
    if mode == "down":
        server.stop()
    else:
        server.set_mode(mode, fail_after or 0)
    try:
        rc = main(_run(out, server.url, 2))
    finally:
        if mode == "down":
            server.start()
        server.set_mode("good")
    captured = capsys.readouterr()
    lines = captured.err.splitlines()
    assert rc == 1, captured.err
    assert len(lines) == 1, captured.err
    line = lines[0]
    assert "Traceback" not in captured.err and "Traceback" not in captured.out
    assert line.startswith(f"pilworld: error: checkpoint {server.url}")
    assert f": {kind}: " in line, line
    if fail_after is not None:
        assert "sort_cubes subtask 1" in line  # the branch that failed: the second pair's first (imagined)
    assert "rerun the same command to resume" in line
    # The first pair stays stored and readable; nothing of the failed pair was committed.
    stored = _pairs(out)
    assert len(stored) == 2 and {o for _, o in stored} == {"imagined", "real"}
    assert all(p.endswith("subtask0") for p, _ in stored)

    # The same command against a good server resumes: only the lost pair runs.
    assert main(_run(out, server.url, 2)) == 0
    summary = json.loads(capsys.readouterr().out.strip().splitlines()[-1])
    assert summary["branches_run"] == 2
    after = _pairs(out)
    assert after[:2] == stored and len(after) == 4
    assert all(p.endswith("subtask1") for p, _ in after[2:])


def test_the_servers_metadata_is_stored_per_checkpoint(server: FaultyServer, one_pair: Path) -> None:
    stored = json.loads((one_pair / METADATA_FILE).read_text())
    assert list(stored) == [server.url]  # a scripted checkpoint has no server, so no entry
    assert stored[server.url]["image_size"] == list(server.size)
    assert stored[server.url]["pilworld"] == {"policy": CKPT, "reset": True}


def test_debug_shows_the_traceback(server: FaultyServer, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """``--debug`` prints the traceback before the one line; the exit status stays 1 (a run failure)."""
    server.stop()
    try:
        assert main(["--debug", *_run(tmp_path / "run", server.url, 1)]) == 1
        err = capsys.readouterr().err
        assert "Traceback (most recent call last)" in err and "unreachable" in err.splitlines()[-1]
    finally:
        server.start()


@pytest.mark.parametrize("case", ["exception reply", "timeout"])
def test_an_imagined_only_run_fails_the_same_way(
    case: str, server: FaultyServer, one_pair: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    # `pilworld imagine` from the one-pair run's starts: the same one line and exit 1, and a rerun resumes.
    mode, _, kind = CASES[case]
    out = tmp_path / "imagined"
    args = ["imagine", "--starts", str(one_pair), "--checkpoints", server.url, "--out", str(out), "--json"]
    server.set_mode(mode, 0)
    try:
        rc = main(args)
    finally:
        server.set_mode("good")
    captured = capsys.readouterr()
    lines = captured.err.splitlines()
    assert rc == 1 and len(lines) == 1, captured.err
    assert lines[0].startswith(f"pilworld: error: checkpoint {server.url}") and f": {kind}: " in lines[0]
    assert "rerun the same command to resume" in lines[0] and "Traceback" not in captured.err
    assert main(args) == 0
    summary = json.loads(capsys.readouterr().out.strip().splitlines()[-1])
    assert summary["branches_run"] == 1
