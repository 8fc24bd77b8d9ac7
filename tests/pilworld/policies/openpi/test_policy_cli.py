"""``pilworld policy serve``: starts, answers /healthz and a client, exits 0 after --max-seconds."""

from __future__ import annotations

import re
import subprocess
import sys
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from pilworld.cli.main import main
from pilworld.config.rig import RigConfig
from pilworld.policies.openpi import OpenPiClient, healthz
from pilworld.policies.scripted import ScriptedPolicy

pytestmark = pytest.mark.timeout(30)
ROOT = Path(__file__).resolve().parents[4]
SIM = ROOT / "configs" / "rig" / "sim_dual_ur5e.yaml"


def test_serve_starts_answers_and_exits_after_max_seconds(robots: Callable[[str], Any]) -> None:
    robot = robots("stack_bowls")
    obs = robot.reset(seed=5, subtask=0, history=0).observation
    direct = ScriptedPolicy(RigConfig.load(SIM), "scripted_step_30k")
    direct.reset(seed=1)
    expected = direct.infer(obs, robot.task.instruction)
    cmd = [sys.executable, "-m", "pilworld.cli.main", "policy", "serve", "--port", "0", "--max-seconds", "2"]
    proc = subprocess.Popen(cmd, cwd=ROOT, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        assert proc.stdout is not None
        first = proc.stdout.readline()
        found = re.search(r"on (ws://127\.0\.0\.1:\d+)", first)
        assert found, first
        url = found.group(1)
        assert healthz(url, timeout=1.0)
        with OpenPiClient(url, connect_timeout=2, reply_timeout=5) as client:
            assert client.metadata["image_size"] == [128, 128] and client.metadata["action_horizon"] == 50
            assert client.metadata["pilworld"]["policy"] == "scripted_step_30k"
            assert client.image_size == (128, 128)
            client.reset(seed=1)
            np.testing.assert_array_equal(client.infer(obs, robot.task.instruction), expected)
        assert proc.wait(timeout=10) == 0
        assert not healthz(url, timeout=0.5)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait(5)


def test_serve_rejects_bad_arguments(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["policy", "serve", "--host", "0.0.0.0", "--port", "0", "--max-seconds", "0.1"]) == 2
    assert "not a loopback address" in capsys.readouterr().err
    assert main(["policy", "serve", "--checkpoint", "nope", "--max-seconds", "0.1"]) == 2
    assert "--checkpoint: unknown 'nope'" in capsys.readouterr().err


def test_serve_in_process_for_the_given_time(capsys: pytest.CaptureFixture[str]) -> None:
    start = time.monotonic()
    assert main(["policy", "serve", "--port", "0", "--max-seconds", "0.3", "--horizon", "20"]) == 0
    assert 0.25 < time.monotonic() - start < 5
    assert "chunks 20×14 for 0.3 s" in capsys.readouterr().out
