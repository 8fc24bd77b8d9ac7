"""``FakeRig`` process failures (at start-up or mid-run): a typed error naming the exit code; ``stop()`` still safe."""

from __future__ import annotations

import os

import pytest

import hw_drivers.fakes.rig as rig_module
from hw_drivers.fakes.rig import FakeRig, FakeRigError

FAKE = "configs/rig/fake_dual_ur5e.yaml"


def test_a_process_that_dies_before_answering_is_a_typed_error(monkeypatch: pytest.MonkeyPatch) -> None:
    # The child runs os._exit(conn, path, seed, subtask): a TypeError, so it exits 1 without a word.
    monkeypatch.setattr(rig_module, "_serve", os._exit)
    fake = FakeRig(FAKE, start_timeout=30.0)  # a timeout would be DeviceTimeoutError: the match below fails
    with pytest.raises(FakeRigError, match=r"exited during start-up \(exit code 1\)"):
        fake.start()
    fake.stop()  # idempotent after a failed start


def test_a_process_that_cannot_be_started_leaves_stop_safe(monkeypatch: pytest.MonkeyPatch) -> None:
    def refuse(self: object) -> None:
        raise OSError("no more processes")

    monkeypatch.setattr("multiprocessing.process.BaseProcess.start", refuse)
    fake = FakeRig(FAKE)
    with pytest.raises(OSError, match="no more processes"):
        fake.start()
    fake.stop()  # was: AssertionError "can only join a started process"


def test_a_process_killed_mid_run_is_a_typed_error_naming_its_exit_code() -> None:
    import signal

    with FakeRig(FAKE) as fake:
        fake.request("state")  # alive and answering
        os.kill(fake._proc.pid, signal.SIGKILL)
        fake._proc.join(10.0)
        # Whether the send still fits the pipe or fails, the caller sees one typed error with the exit code.
        with pytest.raises(FakeRigError, match=r"exited (during|before) 'state' \(exit code -9\)"):
            fake.request("state")
