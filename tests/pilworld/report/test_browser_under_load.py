"""The browser tests pass while every core is busy.

Once, the report's marker-seek test used Chromium's ``--virtual-time-budget`` and failed in a fresh
``scripts/test`` while another process used both cores. This test reproduces that load — one CPU-bound
process per core, each ending itself after a bound — and runs the report's and the annotation app's browser
tests in a child pytest. CI must not depend on an idle machine.
"""

from __future__ import annotations

import os
import subprocess
import sys
import time
from pathlib import Path

import pytest

from pilworld.report.chromium import find_chromium

ROOT = Path(__file__).resolve().parents[3]
BROWSER_TESTS = (
    "tests/pilworld/report/test_browser.py",
    "tests/pilworld/annotate/test_e2e_chromium.py",
)
RUN_LIMIT_S = 300.0  # the browser tests' own bound
# A burner outlives the whole test (its pytest timeout is 2 x RUN_LIMIT_S) and is killed in finally; the
# bound only keeps one from spinning on if the test process itself is killed.
BURN_LIMIT_S = 2 * RUN_LIMIT_S + 60.0
# One CPU-bound loop per core, in a fresh interpreter that imports nothing (-I -S: no site, no .pth files).
# It creates its marker file (argv[2]) once it is in the loop: the test waits for the files, which can never
# block it (a pipe handshake was seen to block a CI run's reader until the burners ended, and the burners'
# CPU time read from /proc was seen not to reach 0.2 s in 600 s on a CI machine).
BURNER = (
    "import sys, time\n"
    "end = time.monotonic() + float(sys.argv[1]); x = 0; marked = False\n"
    "while time.monotonic() < end:\n"
    "    for _ in range(100_000):\n"
    "        x = (x * 1103515245 + 12345) & 0x7FFFFFFF\n"
    "    if not marked:\n"
    "        open(sys.argv[2], 'w').close(); marked = True\n"
)


def wait_spinning(markers: list[Path], burners: list[subprocess.Popen[bytes]], bound_s: float = 60.0) -> float:
    """Until every burner has run one loop of its spin (its marker exists); the seconds that took."""
    t0 = time.monotonic()
    while not all(m.exists() for m in markers):
        waited = time.monotonic() - t0
        assert waited < bound_s, f"burners not spinning after {waited:.0f} s ({[m.exists() for m in markers]})"
        assert all(p.poll() is None for p in burners), f"a burner exited before it spun: {[p.poll() for p in burners]}"
        time.sleep(0.05)
    return time.monotonic() - t0


def usable_cores() -> int:
    """The CPUs this process may run on: its affinity, and a cgroup v2 CPU quota where one is set.

    ``os.cpu_count()`` counts the host's cores; in a container limited to two of them, a burner per host
    core would leave the test a sliver of a CPU instead of the fair share a busy machine gives it."""
    cores = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count() or 2
    try:
        quota, period = Path("/sys/fs/cgroup/cpu.max").read_text().split()[:2]
        if quota != "max":
            cores = min(cores, max(1, round(int(quota) / int(period))))
    except (OSError, ValueError):
        pass
    return max(1, cores)


@pytest.mark.slow  # ~260 s on 2 cores: it runs every browser test again, under load
@pytest.mark.timeout(2 * RUN_LIMIT_S)
@pytest.mark.skipif(find_chromium() is None, reason="no Chromium (scripts/install-chromium.sh installs it)")
def test_browser_tests_pass_with_every_core_busy(tmp_path: Path) -> None:
    t0 = time.monotonic()
    markers = [tmp_path / f"burner{i}.spinning" for i in range(usable_cores())]
    burners = [
        subprocess.Popen(
            [sys.executable, "-I", "-S", "-c", BURNER, str(BURN_LIMIT_S), str(m)],
            stdin=subprocess.DEVNULL,
            stdout=subprocess.DEVNULL,
        )
        for m in markers
    ]
    try:
        # The load is real: every burner is spinning before the browser starts.
        started_s = time.monotonic() - t0
        spun_s = wait_spinning(markers, burners)
        env = {**os.environ, "MUJOCO_GL": os.environ.get("MUJOCO_GL", "egl")}
        proc = subprocess.run(
            [sys.executable, "-m", "pytest", "-q", "-p", "no:cacheprovider", *BROWSER_TESTS],
            cwd=ROOT,
            env=env,
            capture_output=True,
            text=True,
            timeout=RUN_LIMIT_S,
        )
        ended = [p.poll() for p in burners]  # None: still spinning; else its exit status
    finally:
        for p in burners:
            p.kill()
        for p in burners:
            p.wait(timeout=10)
    whole_s = time.monotonic() - t0
    timing = f"burners started in {started_s:.1f} s, spinning {spun_s:.1f} s later; whole test {whole_s:.0f} s"
    tail = (proc.stdout + proc.stderr)[-4000:]
    assert proc.returncode == 0, f"browser tests failed under load ({timing}):\n{tail}"
    # Every test ran (none skipped or deselected) and the cores stayed busy the whole time.
    assert " passed" in proc.stdout and "skipped" not in proc.stdout, tail
    assert ended == [None] * len(burners), f"a burner ended (exit {ended}) before the browser tests finished"
