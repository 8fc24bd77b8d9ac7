"""The Ray backend of ``pilworld imagine`` writes the same dataset as the local one, on a loopback cluster."""

from __future__ import annotations

import dataclasses
import json
import os
import shutil
import signal
import socket
import subprocess
import sys
import tempfile
import time
from collections.abc import Iterator
from pathlib import Path

import numpy as np
import pytest

from pilworld.imagine.runner import ImagineConfig, imagine_run
from pilworld.types import ChunkSpec
from simrig.files import SIM_RIG

RAY = Path(sys.executable).with_name("ray")  # the ray CLI of the interpreter running the tests
SPEC = ChunkSpec(rounds=1)  # one closed-loop round keeps each branch short
CHECKPOINTS = ["scripted_step_30k", "scripted_step_05k"]
START_TIMEOUT_S = 120
STOP_TIMEOUT_S = 60


@pytest.fixture(scope="module")
def starts(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """Two stored starts of ``sort_cubes``, recorded on the simulated rig."""
    from pilworld.collection.collect import dataset_spec
    from pilworld.paired.stations import SimStation
    from pilworld.starts.store import StartsWriter
    from pilworld.types import Subtask
    from simrig.tasks import make_task

    root = tmp_path_factory.mktemp("starts")
    instruction = make_task("sort_cubes").instruction
    with (
        SimStation(str(SIM_RIG), "sort_cubes") as station,
        StartsWriter(
            root, dataset_spec(str(SIM_RIG), "lossless", SPEC), station.robot.spec, SPEC, rig=str(SIM_RIG)
        ) as writer,
    ):
        for i in (0, 1):
            sub = Subtask(task="sort_cubes", index=i, instruction=instruction, seed=7200000)
            writer.add(station.start(sub, "", SPEC))
    return root


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def _stop(proc: subprocess.Popen[bytes]) -> None:
    """Stop the head started by this test, by its process id: SIGTERM shuts down what it started.

    Not ``ray stop --force``, which kills every Ray process of this user on the machine.
    """
    if proc.poll() is None:
        proc.send_signal(signal.SIGTERM)
        try:
            proc.wait(STOP_TIMEOUT_S)
        except subprocess.TimeoutExpired:
            proc.kill()  # its processes share its fate (Ray sets PR_SET_PDEATHSIG under --block)
            proc.wait(STOP_TIMEOUT_S)


@pytest.fixture(scope="module")
def ray_cluster() -> Iterator[str]:
    """A two-CPU Ray head on 127.0.0.1 (two workers), stopped after the module; yields its address."""
    import ray._private.ray_constants as ray_constants

    port = _free_port()
    temp_dir = tempfile.mkdtemp(prefix="pwray-", dir="/tmp")  # short: Ray's socket paths must fit 107 bytes
    # Ray replaces a loopback address with this machine's outward IP, to be reachable by other nodes;
    # the switch it uses on macOS (a single-machine "cluster") keeps everything on 127.0.0.1. Token
    # authentication is off: a head turns it on when ~/.ray/auth_token exists, while a driver given an
    # explicit address does not, and a loopback cluster has nobody to keep out.
    switches = {ray_constants.ENABLE_RAY_CLUSTERS_ENV_VAR: "0", "RAY_AUTH_MODE": "disabled"}
    env = {**os.environ, "RAY_USAGE_STATS_ENABLED": "0", **switches}
    log = Path(temp_dir) / "ray_start.log"
    cmd = [str(RAY), "start", "--head", "--block", "--node-ip-address=127.0.0.1", f"--port={port}"]
    cmd += ["--num-cpus=2", "--include-dashboard=false", "--disable-usage-stats", f"--temp-dir={temp_dir}"]
    # --block: the head stays this child, so the teardown stops exactly the processes this test started.
    with log.open("wb") as out:
        proc = subprocess.Popen(cmd, env=env, stdout=out, stderr=subprocess.STDOUT)
    try:
        deadline = time.monotonic() + START_TIMEOUT_S
        while "Ray runtime started" not in log.read_text(errors="replace"):
            if proc.poll() is not None or time.monotonic() > deadline:
                print(log.read_text(errors="replace"))
                pytest.fail(f"ray start failed (exit {proc.poll()}); its output is printed above")
            time.sleep(0.2)
        with pytest.MonkeyPatch.context() as mp:
            mp.setattr(ray_constants, "ENABLE_RAY_CLUSTER", False)  # read at import: the driver's side of the switch
            mp.setenv("RAY_AUTH_MODE", "disabled")
            yield f"127.0.0.1:{port}"
    finally:
        _stop(proc)
        shutil.rmtree(temp_dir, ignore_errors=True)


def _assert_same_store(a: Path, b: Path) -> None:
    from pilworld.data.reader import EpisodeStore

    sa, sb = EpisodeStore(a), EpisodeStore(b)
    assert len(sa) == len(sb) == 2 * len(CHECKPOINTS)
    assert sa.spec.views == sb.spec.views
    for i in range(len(sa)):
        ea, eb = sa.load(i), sb.load(i)
        assert ea.extra["pair"] == eb.extra["pair"], f"episode {i}"
        assert (ea.checkpoint, ea.seed, ea.origin) == (eb.checkpoint, eb.seed, eb.origin)
        for view in sa.spec.views:
            assert np.array_equal(ea.images[view], eb.images[view]), f"episode {i}, view {view}"
        assert np.array_equal(ea.state, eb.state), f"episode {i} state"
        assert np.array_equal(ea.action, eb.action), f"episode {i} action"
    videos_a = sorted(p.relative_to(a) for p in (a / "videos").rglob("*.mp4"))
    videos_b = sorted(p.relative_to(b) for p in (b / "videos").rglob("*.mp4"))
    assert videos_a == videos_b and videos_a
    for rel in videos_a:
        assert (a / rel).read_bytes() == (b / rel).read_bytes(), str(rel)


# A hang guard, not a speed bound: 13 s idle, 191 s with a CPU-bound process on each of 2 cores (Ray's head,
# raylet and workers share what the burners leave), which ran past the earlier 180 s in a loaded scripts/test.
@pytest.mark.timeout(600)
def test_ray_run_writes_the_local_runs_dataset(starts: Path, ray_cluster: str, tmp_path: Path) -> None:
    from pilworld.imagine.ray_backend import ray_backend

    def cfg(out: str) -> ImagineConfig:
        return ImagineConfig(starts=str(starts), checkpoints=CHECKPOINTS, out=str(tmp_path / out), spec=SPEC)

    local = imagine_run(cfg("local"), workers=1, progress=False)
    remote = imagine_run(cfg("ray"), backend=ray_backend(ray_cluster), progress=False)
    assert local["branches_run"] == remote["branches_run"] == 2 * len(CHECKPOINTS)
    _assert_same_store(tmp_path / "local", tmp_path / "ray")

    import ray

    assert not ray.is_initialized()  # the backend shut down the connection it made


@pytest.mark.timeout(400)  # 69-105 s under the same load
def test_a_failing_job_raises_its_own_error(starts: Path, ray_cluster: str, tmp_path: Path) -> None:
    import ray

    from pilworld.data.reader import DatasetError
    from pilworld.imagine.ray_backend import ray_backend
    from pilworld.imagine.runner import plan_jobs, robot_spec_for, run_job
    from pilworld.starts.sources import load_starts
    from pilworld.starts.store import robot_spec_json

    cfg = ImagineConfig(starts=str(starts), checkpoints=CHECKPOINTS, out=str(tmp_path), rig=str(SIM_RIG), spec=SPEC)
    source = load_starts(cfg.starts, history=SPEC.history, start_frame=None)
    jobs = plan_jobs(cfg, source)
    jobs[1] = dataclasses.replace(jobs[1], starts_root=str(tmp_path / "missing"))
    cfg_json, robot = json.loads(json.dumps(cfg.to_json())), robot_spec_json(robot_spec_for(cfg, source))
    with pytest.raises(DatasetError) as local:
        run_job(jobs[1], cfg_json, robot)
    with pytest.raises(DatasetError) as remote:  # the worker's own error, not Ray's wrapper
        list(ray_backend(ray_cluster)(jobs, cfg_json, robot))
    assert str(remote.value) == str(local.value)
    assert not ray.is_initialized()


@pytest.mark.timeout(120)
def test_unreachable_address_names_it() -> None:
    from pilworld.imagine.ray_backend import ray_backend

    t0 = time.monotonic()
    with pytest.raises(ValueError, match=r"127\.0\.0\.1:1"):
        ray_backend("127.0.0.1:1")
    assert time.monotonic() - t0 < 30
