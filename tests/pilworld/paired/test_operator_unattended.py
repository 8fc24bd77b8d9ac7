"""A hardware-path paired run without a terminal: one line saying an operator is needed, before any motion;
``--unattended`` runs it on the fake rig (the simulator lays out and judges) and is refused on a real rig."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

FAKE = "configs/rig/fake_dual_ur5e.yaml"
REAL = "configs/rig/real_dual_ur5e.yaml"


def _paired(out: Path, *extra: str, rig: str = FAKE) -> subprocess.CompletedProcess[str]:
    cmd = [sys.executable, "-m", "pilworld.cli.main", "paired", "run", "--rig", rig, "--task", "sort_cubes",
           "--subtasks", "1", "--rounds", "1", "--out", str(out), *extra]  # fmt: skip
    env = {**os.environ, "MUJOCO_GL": os.environ.get("MUJOCO_GL", "egl")}
    return subprocess.run(cmd, stdin=subprocess.DEVNULL, capture_output=True, text=True, env=env, timeout=600)


def test_no_terminal_means_one_line_and_no_motion(tmp_path: Path) -> None:
    out = tmp_path / "run"
    done = _paired(out)
    assert done.returncode == 1, done.stderr
    lines = done.stderr.strip().splitlines()
    assert len(lines) == 1 and "Traceback" not in done.stderr, done.stderr
    assert lines[0].startswith("pilworld: error:") and "operator" in lines[0] and "--unattended" in lines[0]
    assert not out.exists(), "nothing may be written (or moved) before an operator is known to be there"


def test_unattended_runs_on_the_fake_rig(tmp_path: Path) -> None:
    out = tmp_path / "run"
    done = _paired(out, "--unattended", "--json")
    assert done.returncode == 0, done.stderr[-3000:]
    summary = json.loads(done.stdout.strip().splitlines()[-1])
    assert summary["branches_run"] == 2
    assert (out / "meta" / "info.json").is_file()


def test_unattended_is_refused_on_a_real_rig(tmp_path: Path) -> None:
    # The real rig's config at the model's image size; nothing connects: the refusal comes first.
    text = Path(REAL).read_text(encoding="utf-8")
    text = text.replace("image_size: {width: 224, height: 224}", "image_size: {width: 128, height: 128}")
    text = text.replace("file: ../calib/", f"file: {Path(REAL).resolve().parents[1] / 'calib'}/")
    rig = tmp_path / "real.yaml"
    rig.write_text(text, encoding="utf-8")
    out = tmp_path / "run"
    done = _paired(out, "--unattended", rig=str(rig))
    assert done.returncode == 2, done.stderr
    assert "--unattended" in done.stderr and "Traceback" not in done.stderr
    assert not out.exists()
