"""Running an imagined-only run's branches on a Ray cluster (``pilworld imagine … --ray ADDRESS``).

A drop-in :data:`~pilworld.imagine.runner.Backend`: each :class:`~pilworld.imagine.runner.ImagineJob`
becomes a Ray task (one CPU) that calls :func:`~pilworld.imagine.runner.run_job` in a Ray worker, which
keeps its world model and policies between jobs as a worker process of the local backend does. Jobs are
submitted in a bounded window and their results handed back strictly in job order, so the run writes
the same dataset as the local backend, bit for bit, and the driver holds at most a window of episodes.

Pointing it at a cluster::

    ray start --head --port 6379 --node-ip-address HEAD_IP     # on the head machine
    ray start --address HEAD_IP:6379                            # on every worker machine
    pilworld imagine … --ray HEAD_IP:6379                       # on any machine of the cluster

``--ray auto`` finds a cluster started on this machine, ``--ray ray://HOST:10001`` goes through Ray
Client, and ``--ray local`` starts a private Ray instance in this process (all of this machine's CPUs)
that stops with the run.

Every machine of the cluster needs pilworld (the same version) installed, and must read the starts
folder at the same path as the driver: jobs name their start by folder and episode, not by content, so
on several machines the starts must lie on a shared file system (NFS and the like). On one machine that
always holds. The episodes come back to the driver, which alone writes the output folder. A cluster
with Ray's token authentication on (a head turns it on when ``~/.ray/auth_token`` exists) needs
``RAY_AUTH_MODE=token`` and the same token on the driver too.
"""

from __future__ import annotations

import contextlib
import os
import socket
from collections.abc import Iterator, Sequence
from typing import Any, NoReturn

from pilworld.imagine.runner import Backend, ImagineJob, JobResult, run_job

LOCAL = "local"  # the address that starts a private Ray instance in this process
CONNECT_TIMEOUT_S = 5.0  # how long the reachability probe of an address waits


class RaySetupError(ValueError):
    """Ray is missing, or the cluster named by ``--ray`` cannot be reached."""


class RayClusterError(RuntimeError):
    """The cluster lost a job (a worker or node died, a task was cancelled)."""


def _import_ray() -> Any:
    try:
        import ray
    except ImportError:
        raise RaySetupError("--ray: Ray is not installed; pip install 'pilworld[ray]'") from None
    return ray


def _probe(address: str) -> None:
    """Fail fast when nothing listens at a ``HOST:PORT`` address: Ray itself retries for many minutes."""
    if address in (LOCAL, "auto"):
        return
    host, sep, port = address.removeprefix("ray://").rpartition(":")
    if not sep or not port.isdigit():
        raise RaySetupError(f"--ray: expected HOST:PORT, ray://HOST:PORT, auto or local, got {address!r}")
    try:
        socket.create_connection((host.strip("[]"), int(port)), timeout=CONNECT_TIMEOUT_S).close()
    except OSError as err:
        raise RaySetupError(f"--ray: cannot reach a Ray cluster at {address!r} ({err.strerror or err})") from None


def _connect(ray: Any, address: str) -> bool:
    """Connect to ``address`` (or start a private instance for ``local``); True when this call connected."""
    _probe(address)
    if ray.is_initialized():
        return False  # the caller connected already; leave its connection (and its shutdown) to it
    try:
        if address == LOCAL:
            # address="local", not None: None would join the cluster last started on this machine.
            ray.init(address=LOCAL, num_cpus=os.cpu_count(), include_dashboard=False)
        else:
            ray.init(address=address)
    except (ConnectionError, RuntimeError, TimeoutError) as err:
        reason = (str(err).strip().splitlines() or [type(err).__name__])[0]
        raise RaySetupError(f"--ray: cannot reach a Ray cluster at {address!r} ({reason})") from None
    return True


def _window(ray: Any, max_in_flight: int | None) -> int:
    """Jobs in flight at once: ``max_in_flight``, else twice the cluster's CPUs (workers never wait)."""
    if max_in_flight is not None:
        return max_in_flight
    cpus = int(ray.cluster_resources().get("CPU", 1))
    return 2 * max(cpus, 1)


def _run_job_threads(job: ImagineJob, cfg_json: dict[str, Any], robot: dict[str, Any], threads: int) -> JobResult:
    """:func:`run_job` with torch on the driver's thread count (Ray workers get ``OMP_NUM_THREADS=1``)."""
    import torch

    # Measured on a 2-CPU machine (torch 2.13 CPU, the packaged world model, 2 starts × 2 checkpoints,
    # one round): on one thread instead of the local path's two, 1 to 3 pixels per imagined view of
    # each episode came out one level apart (float sums split, so rounded, differently); state and
    # action were equal. On the driver's thread count the episodes are equal bit for bit, at the cost
    # of more threads than the task's one reserved CPU. Machines with other CPU kernels (another
    # instruction set) may still round differently: bit-equal datasets need alike machines.
    if torch.get_num_threads() != threads:
        torch.set_num_threads(threads)
    return run_job(job, cfg_json, robot)


def _raise_task_error(ray: Any, err: Exception, job: ImagineJob) -> NoReturn:
    """Re-raise a failed job's own exception where Ray kept it; a lost job as :class:`RayClusterError`."""
    if isinstance(err, ray.exceptions.RayTaskError):
        cause = err.cause
        if isinstance(cause, Exception) and not isinstance(cause, ray.exceptions.RayError):
            raise cause from err  # the worker's error as the local backend raises it; Ray's traceback chained
        raise err.as_instanceof_cause() from None
    first = (str(err).strip().splitlines() or [""])[0]
    raise RayClusterError(f"--ray: job {job.order} ({job.pair_id}) was lost: {type(err).__name__}: {first}") from err


def _cancel(ray: Any, refs: Sequence[Any]) -> None:
    for ref in refs:
        # Best effort: a task that finished meanwhile, or a connection already lost, has nothing to cancel.
        with contextlib.suppress(Exception):
            ray.cancel(ref)


def ray_backend(address: str, *, max_in_flight: int | None = None) -> Backend:
    """A backend running each job as a Ray task on the cluster at ``address`` (or ``local``).

    Connects now, so a missing Ray or an unreachable cluster fails before any work; the connection
    this makes is shut down when the run's results are exhausted or abandoned (a backend never run
    keeps it until the process exits). A connection the caller made is used and left open.
    """
    if not address.strip():
        raise RaySetupError("--ray: expected a cluster address (HOST:PORT, ray://HOST:PORT, auto or local)")
    if max_in_flight is not None and max_in_flight < 1:
        raise RaySetupError(f"max_in_flight: expected at least 1 job in flight, got {max_in_flight}")
    ray = _import_ray()
    connected = [_connect(ray, address)]  # a list: the first run uses this connection, later ones reconnect

    def run(jobs: Sequence[ImagineJob], cfg_json: dict[str, Any], robot: dict[str, Any]) -> Iterator[JobResult]:
        started = connected.pop() if connected else _connect(ray, address)
        try:
            yield from _ordered_results(ray, jobs, cfg_json, robot, _window(ray, max_in_flight))
        finally:
            if started:
                ray.shutdown()

    return run


def _ordered_results(
    ray: Any, jobs: Sequence[ImagineJob], cfg_json: dict[str, Any], robot: dict[str, Any], window: int
) -> Iterator[JobResult]:
    """Results of ``jobs`` in their order, at most ``window`` submitted and not yet handed back."""
    import torch

    task = ray.remote(num_cpus=1)(_run_job_threads)
    cfg_ref, robot_ref = ray.put(cfg_json), ray.put(robot)  # stored once, not once per job
    threads = torch.get_num_threads()
    pending: dict[int, Any] = {}  # position in ``jobs`` → its task's result
    held: dict[int, JobResult] = {}  # finished ahead of their turn
    submitted = 0
    try:
        for turn in range(len(jobs)):
            while submitted < len(jobs) and submitted - turn < window:
                pending[submitted] = task.remote(jobs[submitted], cfg_ref, robot_ref, threads)
                submitted += 1
            while turn not in held:
                # Wait for whichever finishes first rather than for this turn's job, so a failing job
                # stops the run when it fails, not when its turn comes.
                ready, _ = ray.wait(list(pending.values()), num_returns=1)
                index = next(i for i, ref in pending.items() if ref == ready[0])
                ref = pending.pop(index)
                try:
                    held[index] = ray.get(ref)
                except ray.exceptions.RayError as err:
                    _raise_task_error(ray, err, jobs[index])
            yield held.pop(turn)
    finally:
        _cancel(ray, list(pending.values()))
