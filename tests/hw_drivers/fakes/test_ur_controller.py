"""FakeURController (in this process) against the real ur_rtde 1.6.5 client (in a subprocess: its
constructors hold the GIL, so client and fake must never share a process)."""

from __future__ import annotations

import json
import subprocess
import sys
import time
from collections.abc import Iterator
from typing import Any

import numpy as np
import pytest

from hw_drivers.fakes.backend import KinematicBackend
from hw_drivers.fakes.ur_controller import FakeURController
from tests.hw_drivers.ur.fake_process import random_host

pytestmark = pytest.mark.timeout(60)

# The client reports one JSON object per line; the last line is the result.
CLIENT_MOTION = r"""
import json, sys, time
import dashboard_client, rtde_control, rtde_receive
host = sys.argv[1]
out = {}
db = dashboard_client.DashboardClient(host); db.connect()
out["version"] = db.polyscopeVersion(); out["robotmode"] = db.robotmode(); out["safety"] = db.safetystatus()
out["remote"] = db.isInRemoteControl(); out["serial"] = db.getSerialNumber()
c = rtde_control.RTDEControlInterface(host, 500.0)
r = rtde_receive.RTDEReceiveInterface(host, 500.0)  # every default variable
out["running"] = c.isProgramRunning(); out["db_running"] = db.running(); out["status"] = c.getRobotStatus()
t = r.getTimestamp()  # the fake's simulated clock (control cycles x 2 ms), immune to a loaded machine
out["movej"] = c.moveJ([0.4, 0.2, 0.0, 0.0, 0.0, 0.0], 0.8, 1.0)
# rtde_receive is a connection of its own: on a loaded machine its latest sample may predate the one that
# told rtde_control the move ended. Read on until a sample from after the move arrives (bounded).
t_wait = time.monotonic()
while max(abs(a - b) for a, b in zip(r.getActualQ(), [0.4, 0.2, 0, 0, 0, 0])) >= 1e-3 and time.monotonic() - t_wait < 2:
    time.sleep(0.002)
out["movej_sim_s"] = r.getTimestamp() - t  # to the first sample at the target: the move's end
out["q_after_movej"] = r.getActualQ()
out["watchdog"] = c.setWatchdog(10.0)
n, t = 0, time.monotonic()
while time.monotonic() - t < 1.0:
    t0 = c.initPeriod()
    c.servoJ([0.4 + 0.2 * (time.monotonic() - t), 0.2, 0.0, 0.0, 0.0, 0.0], 0.0, 0.0, 0.002, 0.1, 300)
    n += 1
    c.waitPeriod(t0)
out["servo_calls"] = n
out["servostop"] = c.servoStop()
time.sleep(0.05)
out["q_after_servo"] = r.getActualQ(); out["bits"] = r.getSafetyStatusBits(); out["mode"] = r.getRobotMode()
c.stopJ(2.0)
c.stopScript()
out["running_after_stop"] = c.isProgramRunning()
print(json.dumps(out), flush=True)
"""

CLIENT_WAIT = r"""
import json, os, sys, time
import dashboard_client, rtde_control, rtde_receive
host = sys.argv[1]
c = rtde_control.RTDEControlInterface(host, 500.0)
r = rtde_receive.RTDEReceiveInterface(host, 500.0, ["timestamp", "actual_q", "safety_status_bits", "runtime_state"])
print(json.dumps({"ready": True}), flush=True)
sys.stdin.readline()  # the test injects a fault, then says go
t = time.monotonic()
samples = []
while time.monotonic() - t < 1.0:
    samples.append([time.monotonic() - t, r.getTimestamp(), r.getActualQ()[0], r.getSafetyStatusBits(),
                    r.getRuntimeState(), r.isConnected(), r.isProtectiveStopped()])
    time.sleep(0.02)
out = {"samples": samples}
if sys.argv[2] == "protective_stop":
    db = dashboard_client.DashboardClient(host); db.connect()
    out["safety"] = db.safetystatus()
    db.closeSafetyPopup(); db.unlockProtectiveStop()
    c.reuploadScript()
    t = time.monotonic()
    while not c.isProgramRunning() and time.monotonic() - t < 5:
        time.sleep(0.01)
    out["running_after_recover"] = c.isProgramRunning(); out["bits_after_recover"] = r.getSafetyStatusBits()
print(json.dumps(out), flush=True)
os._exit(0)  # skip ur_rtde's destructors: on a stalled link they reconnect and block forever
"""


@pytest.fixture
def fake() -> Iterator[FakeURController]:
    backend = KinematicBackend(arm_speed=4.0)
    with FakeURController(backend, "left", random_host()) as f:
        yield f
    backend.close()


def run_client(code: str, host: str, timeout: float = 30.0) -> dict[str, Any]:
    done = subprocess.run([sys.executable, "-c", code, host], capture_output=True, text=True, timeout=timeout)
    assert done.returncode == 0, done.stderr
    result: dict[str, Any] = json.loads(done.stdout.strip().splitlines()[-1])
    return result


def test_real_client_dashboard_movej_servoj(fake: FakeURController) -> None:
    out = run_client(CLIENT_MOTION, fake.host)
    assert out["version"] == "5.11.1.108318" and out["robotmode"] == "Robotmode: RUNNING"
    assert out["safety"] == "Safetystatus: NORMAL" and out["remote"] is True and out["serial"] == "20185500000"
    assert out["running"] is True and out["db_running"] is True and out["status"] == 3  # powered | running
    assert out["movej"] is True and 0.4 / 0.8 * 0.95 < float(out["movej_sim_s"]) < 0.8  # blocking, at the speed
    np.testing.assert_allclose(out["q_after_movej"], [0.4, 0.2, 0, 0, 0, 0], atol=1e-3)
    assert out["watchdog"] is True
    assert int(out["servo_calls"]) > 0  # the servo rate is a benchmark figure, not a test assertion
    assert out["servostop"] is True
    assert float(out["q_after_servo"][0]) == pytest.approx(0.6, abs=0.02)
    assert out["bits"] == 1 and out["mode"] == 7  # normal, running
    assert out["running_after_stop"] is False and not fake.program_running


def wait_client(fake: FakeURController, fault: str | None) -> dict[str, Any]:
    """Connect the client, inject ``fault``, let it sample for 1 s."""
    proc = subprocess.Popen(
        [sys.executable, "-c", CLIENT_WAIT, fake.host, str(fault)],
        stdin=subprocess.PIPE,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    try:
        assert proc.stdout is not None and proc.stdin is not None
        assert json.loads(proc.stdout.readline()) == {"ready": True}
        if fault is not None:
            fake.faults.inject(fault)
        proc.stdin.write("go\n")
        proc.stdin.flush()
        out, err = proc.communicate(timeout=30)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
    assert proc.returncode == 0, err
    result: dict[str, Any] = json.loads(out.strip().splitlines()[-1])
    return result


def test_protective_stop_seen_by_client_and_unlocked(fake: FakeURController) -> None:
    out = wait_client(fake, "protective_stop")
    samples = out["samples"]
    assert isinstance(samples, list)
    stopped = [s for s in samples if s[6]]
    assert stopped and stopped[0][0] < 0.1  # protective stop bit within 100 ms
    assert stopped[-1][3] == (1 << 2) | (1 << 10) and stopped[-1][4] == 1  # bits; runtime STOPPED
    assert out["safety"] == "Safetystatus: PROTECTIVE_STOP"
    assert out["running_after_recover"] is True and out["bits_after_recover"] == 1


@pytest.mark.parametrize("fault", ["drop", "stall", "corrupt", "disconnect"])
def test_stream_faults_seen_by_client(fake: FakeURController, fault: str) -> None:
    out = wait_client(fake, fault)
    samples = out["samples"]
    assert isinstance(samples, list)
    late = [s for s in samples if s[0] > 0.2]
    if fault == "corrupt":
        assert all(np.isnan(s[2]) for s in late)  # garbage decoded as NaN joints
    else:
        assert len({s[1] for s in late}) == 1  # the controller timestamp froze
    if fault == "disconnect":
        assert not late[-1][5]


def test_watchdog_stops_program(fake: FakeURController) -> None:
    code = r"""
import sys, time, rtde_control
c = rtde_control.RTDEControlInterface(sys.argv[1], 500.0)
c.setWatchdog(10.0)
c.servoJ([0.3, 0, 0, 0, 0, 0], 0.0, 0.0, 0.002, 0.1, 300)
time.sleep(0.5)  # no input for longer than 1 / 10 Hz
print('{"running": %s}' % str(c.isProgramRunning()).lower(), flush=True)
"""
    assert run_client(code, fake.host) == {"running": False}
    assert not fake.program_running


def test_two_arms_share_a_backend() -> None:
    backend = KinematicBackend(arm_speed=4.0)
    base = random_host().rsplit(".", 1)[0]
    code = r"""
import sys, time, rtde_control
c = rtde_control.RTDEControlInterface(sys.argv[1], 500.0)
q = [float(sys.argv[2])] + [0.0] * 5
print('{"ok": %s}' % str(c.moveJ(q, 2.0, 2.0)).lower(), flush=True)
"""
    with (
        FakeURController(backend, "left", f"{base}.1") as left,
        FakeURController(backend, "right", f"{base}.2") as right,
    ):
        for fake, q in ((left, "0.3"), (right, "-0.2")):
            done = subprocess.run(
                [sys.executable, "-c", code, fake.host, q], capture_output=True, text=True, timeout=30
            )
            assert json.loads(done.stdout) == {"ok": True}, done.stderr
        time.sleep(0.05)
        assert backend.arm_q("left")[0] == pytest.approx(0.3, abs=1e-3)
        assert backend.arm_q("right")[0] == pytest.approx(-0.2, abs=1e-3)
    backend.close()
