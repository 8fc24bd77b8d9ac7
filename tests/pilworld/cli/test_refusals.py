"""Every case of the issue "A refused command writes nothing", through the CLI (tests/pilworld/cli/misuse_cases.py).

Each case asserts the exit status, exactly one ``pilworld: error:`` line (no traceback, no signal, no raw
library message) and that its ``--out`` folder, the folders it names and the shared workspace are
byte-identical before and after. The cases that are refused before any data is read run against marker-only
folders (fast); the others against real run folders of every kind (built once per module, about a minute:
slow). ``scripts/misuse-sweep`` runs the whole sweep (``SWEEP_CASES``); the slow test below runs it too.
"""

from __future__ import annotations

from pathlib import Path

import pytest

from tests.pilworld.cli import misuse
from tests.pilworld.cli.misuse_cases import ISSUE_CASES, SWEEP_CASES

# Refused before any episode is read: the marker-only workspace is enough.
FAST = {
    "paired-into-collection",
    "paired-negative-seed",
    "paired-malformed-ws",
    "paired-ws-bad-port",
    "record-starts-into-paired",
    "paired-into-imagined",
    "collect-into-paired",
    "collect-into-starts",
    "imagine-into-paired",
    "imagine-into-collection",
    "record-starts-into-collection",
    "convert-into-paired",
    "paired-wm-truncated",
    "paired-wm-random",
    "paired-wm-bad-config",
    "info-wrong-shape-list",
    "info-wrong-shape-features",
    "verify-wrong-shape",
    "report-wrong-shape",
    "cv-empty-actions",
    "cv-empty-previous-state",
    "plan-trials-tiny-half-width",
    "annotate-judges-huge",
    "paired-subtasks-huge",
    "cv-nonutf8-out",
    "sim-show-nonutf8-out",
    "imagine-start-frame-paired",
    "collect-workers-negative",
    "bench-sim-subtasks-zero",
    "bench-sim-subtasks-negative",
    "cv-joints-1e6",
    "collect-out-is-file",
    "cv-out-is-folder",
    "cv-binary-rig",
    "paired-binary-rig",
    "task-check-binary",
    "report-out-unwritable",
    "debug-usage-error",
    "debug-bad-value",
    "debug-damaged-weights",
}


@pytest.fixture(scope="module")
def marker_ws(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return misuse.build_marker_workspace(tmp_path_factory.mktemp("markers"))


@pytest.fixture(scope="module")
def real_ws(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return misuse.build_workspace(tmp_path_factory.mktemp("runs"))


def _check(case: misuse.Case, ws: Path, scratch: Path) -> None:
    result = misuse.run_case(case, ws, scratch)
    assert not result.problems(), (
        f"{case.name}: {'; '.join(result.problems())}\nexit {result.rc}\nstderr:\n{result.stderr[-3000:]}"
    )


def test_every_issue_case_is_in_the_sweep() -> None:
    assert {c.name for c in ISSUE_CASES} <= {c.name for c in SWEEP_CASES}
    assert {c.name for c in ISSUE_CASES} >= FAST
    assert len(SWEEP_CASES) >= 250


@pytest.mark.parametrize("case", [c for c in ISSUE_CASES if c.name in FAST], ids=lambda c: c.name)
def test_refused_without_a_trace_fast(case: misuse.Case, marker_ws: Path, tmp_path: Path) -> None:
    _check(case, marker_ws, tmp_path)


@pytest.mark.slow
@pytest.mark.parametrize("case", ISSUE_CASES, ids=lambda c: c.name)
def test_refused_without_a_trace(case: misuse.Case, real_ws: Path, tmp_path: Path) -> None:
    """Every issue case against real run folders (the fast ones again, on real data)."""
    _check(case, real_ws, tmp_path)


@pytest.mark.slow
def test_the_sweep(real_ws: Path, tmp_path: Path) -> None:
    """The whole sweep (≥ 250 misuses of every command): no traceback, no signal, no silent acceptance, no loss."""
    failed = []
    for result in misuse.run_cases(SWEEP_CASES, real_ws, tmp_path):
        if result.problems():
            failed.append(f"{result.case.name}: {'; '.join(result.problems())} | {result.first_line[:200]}")
    assert not failed, "\n".join(failed)
