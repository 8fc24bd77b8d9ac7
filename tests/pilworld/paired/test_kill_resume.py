"""Kill -9 a paired run midway; rerunning the same command finishes it with the uninterrupted result."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from pilworld.data.reader import EpisodeStore
from tests.pilworld.paired.digest import dataset_digest

SIM = "configs/rig/sim_dual_ur5e.yaml"


def _cmd(out: Path) -> list[str]:
    return [
        sys.executable, "-m", "pilworld.cli.main", "paired", "run", "--rig", SIM, "--task", "sort_cubes",
        "--subtasks", "3", "--rounds", "2", "--out", str(out), "--json",
    ]  # fmt: skip


@pytest.mark.slow
def test_sigkill_midway_then_rerun_equals_uninterrupted(tmp_path: Path) -> None:
    env = {**os.environ, "MUJOCO_GL": os.environ.get("MUJOCO_GL", "egl")}
    ref = tmp_path / "ref"
    subprocess.run(_cmd(ref), check=True, env=env, capture_output=True, timeout=600)

    out = tmp_path / "killed"
    proc = subprocess.Popen(_cmd(out), env=env, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    timings = out / "paired_timings.jsonl"
    deadline = time.monotonic() + 300
    while time.monotonic() < deadline and proc.poll() is None:
        if timings.is_file() and len(timings.read_text().splitlines()) >= 3:
            break
        time.sleep(0.05)
    assert proc.poll() is None, "the run finished before it could be killed"
    proc.send_signal(signal.SIGKILL)
    proc.wait(timeout=30)
    # What the killed run had committed: the rerun must redo exactly the rest, not everything.
    stored = EpisodeStore(out).num_episodes
    total = EpisodeStore(ref).num_episodes
    assert 0 < stored < total, (stored, total)
    done = subprocess.run(_cmd(out), check=True, env=env, capture_output=True, text=True, timeout=600)
    summary = json.loads(done.stdout.strip().splitlines()[-1])
    assert summary["branches_run"] == total - stored, (summary["branches_run"], total, stored)
    assert dataset_digest(out) == dataset_digest(ref)
