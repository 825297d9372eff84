"""Captures as Ray tasks: one task per capture, with its CPU and GPU requirement.

Ray (https://docs.ray.io) is used because it is the common way labs share a cluster: the same
command that runs on a laptop runs on an existing cluster (``--ray ADDRESS``), Ray's scheduler
places each task where its resources are free, and Ray re-runs a task whose worker process died
(``max_retries``; a capture's own errors come back as outcomes and are never retried). It is an
optional extra (``pip install 'artgs[batch]'``), imported only here and only with ``--ray``.

Without ADDRESS a private Ray is started on 127.0.0.1 with ``workers x cpus`` CPUs and stopped
at the end. With a cluster, capture folders and DIR must be on a file system every node sees
at the same path, and ``artgs`` must be installed on every node.
"""

from __future__ import annotations

import os
import sys
import time
from typing import Any, Callable

from ..model.errors import ArtgsError
from .jobs import Job
from .worker import Outcome, run_job

CANCEL_GRACE = 30.0   # seconds cancelled tasks get to stop before their workers are killed


# Ray resolves 127.0.0.1 to the machine's outward address unless it runs "without clusters"
# (read when ray is imported); a private Ray must stay on the loopback interface.
_LOOPBACK_ONLY = "RAY_ENABLE_WINDOWS_OR_OSX_CLUSTER"


def _ray(private: bool) -> Any:
    if private and "ray" not in sys.modules:
        os.environ[_LOOPBACK_ONLY] = "0"
    try:
        import ray
    except ImportError:
        raise ArtgsError("--ray needs Ray: pip install 'artgs[batch]' "
                         "(or run without --ray on a local process pool)") from None
    return ray


def _task(job: Job, stage_options: dict[str, Any]) -> Outcome:
    """The Ray task: threads from the CPUs Ray gave it (Ray also sets OMP_NUM_THREADS)."""
    import ray

    cpus = ray.get_runtime_context().get_assigned_resources().get("CPU", 1.0)
    return run_job(job, stage_options, max(1, int(cpus)))


def run_ray(jobs: list[Job], stage_options: dict[str, Any], address: str | None, workers: int,
            cpus: int, gpus: float, retries: int,
            started: Callable[[Job, int], None], ended: Callable[[Job, Outcome], None],
            retrying: Callable[[Job, str], None]) -> None:  # noqa: ARG001 - Ray retries itself
    """Run ``jobs`` as Ray tasks on a local Ray (``address`` None) or the cluster at ``address``."""
    own = address is None
    ray = _ray(own)
    env = {"OMP_WAIT_POLICY": os.environ.get("OMP_WAIT_POLICY", "PASSIVE")}
    if own:
        ray.init(address="local", _node_ip_address="127.0.0.1", num_cpus=workers * cpus,
                 include_dashboard=False, log_to_driver=False, configure_logging=False,
                 runtime_env={"env_vars": env})
    else:
        ray.init(address=address, log_to_driver=False, configure_logging=False,
                 runtime_env={"env_vars": env})
    try:
        _check_resources(ray.cluster_resources(), cpus, gpus)
    except ArtgsError:
        ray.shutdown()
        raise
    remote = ray.remote(_task).options(num_cpus=cpus, num_gpus=gpus, max_retries=retries)
    pending: dict[Any, Job] = {}
    waiting = set()     # submitted, not yet started (a task starts by writing its log)
    try:
        for job in jobs:
            pending[remote.remote(job, stage_options)] = job
            waiting.add(job)
        while pending:
            ready, _ = ray.wait(list(pending), num_returns=1, timeout=1.0)
            for job in [j for j in waiting if _log_started(j)]:
                waiting.discard(job)
                started(job, 0)
            for ref in ready:
                job = pending.pop(ref)
                waiting.discard(job)
                try:
                    ended(job, ray.get(ref))
                except ray.exceptions.RayError as exc:
                    first = str(exc).strip().splitlines()[0] if str(exc).strip() else repr(exc)
                    ended(job, Outcome("died", f"{type(exc).__name__}: {first}; "
                                               f"gave up after {retries + 1} attempts",
                                       attempt=retries + 1))
    except KeyboardInterrupt:
        _cancel(ray, list(pending))
        raise
    finally:
        if own:
            ray.shutdown()


def _check_resources(have: dict[str, float], cpus: int, gpus: float) -> None:
    """Refuse a task size no node can hold (Ray would otherwise wait for it forever)."""
    for name, need in (("CPU", cpus), ("GPU", gpus)):
        if need > have.get(name, 0.0):
            raise ArtgsError(f"each capture asks for {need:g} {name}(s) but the Ray cluster has "
                             f"{have.get(name, 0.0):g}; lower --{name.lower()}s-per-capture")


def _log_started(job: Job) -> bool:
    try:
        return job.log.stat().st_size > 0
    except OSError:
        return False


def _cancel(ray: Any, refs: list[Any]) -> None:
    """Cancel tasks (a KeyboardInterrupt in each, so it stops like a Ctrl-C); force after a grace."""
    for ref in refs:
        ray.cancel(ref, force=False)
    deadline = time.monotonic() + CANCEL_GRACE
    while refs and time.monotonic() < deadline:
        _, refs = ray.wait(refs, num_returns=len(refs), timeout=1.0)
    for ref in refs:
        ray.cancel(ref, force=True)
