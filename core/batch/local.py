"""The local pool: up to N worker processes, each pinned to its share of this machine's cores.

One fresh process per capture (``spawn``: no torch or OpenMP state inherited from the driver),
started in a worker *slot*; slot ``i`` owns cores ``cores[i::N]`` (``os.sched_setaffinity``) and
runs torch, numba and BLAS with that many threads. A process that ends without an outcome (killed,
out of memory, a crash in native code) is started again, up to ``retries`` more times. On Ctrl-C
the workers are stopped (SIGTERM, which they turn into a cancel; files in OUT are written
atomically) and :class:`KeyboardInterrupt` is raised to the caller.
"""

from __future__ import annotations

import multiprocessing as mp
import os
import signal
from collections import deque
from dataclasses import dataclass
from multiprocessing.connection import Connection, wait
from typing import Any, Callable

from .jobs import Job
from .worker import Outcome, limit_threads_env, run_job

STOP_GRACE = 30.0   # seconds a cancelled worker gets to stop before it is killed


def core_shares(workers: int, cores: list[int] | None = None) -> list[list[int]]:
    """Cores of each worker slot: round-robin over the usable cores (shared if fewer cores)."""
    cores = sorted(cores if cores is not None else os.sched_getaffinity(0))
    if workers <= len(cores):
        return [cores[i::workers] for i in range(workers)]
    return [[cores[i % len(cores)]] for i in range(workers)]


def _child(job: Job, stage_options: dict[str, Any], cores: list[int], conn: Connection) -> None:
    """Worker process body: pin, limit threads, run, send the outcome."""
    signal.signal(signal.SIGTERM, _raise_interrupt)
    try:
        os.sched_setaffinity(0, cores)
        limit_threads_env(len(cores))
        outcome = run_job(job, stage_options, len(cores))
    except KeyboardInterrupt:   # stopped before run_job could catch it
        outcome = Outcome("cancelled", "cancelled", pid=os.getpid())
    # a second Ctrl-C (the terminal's SIGINT, then the driver's SIGTERM) must not lose the outcome
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    signal.signal(signal.SIGTERM, signal.SIG_IGN)
    conn.send(outcome)
    conn.close()


def _raise_interrupt(signum, frame) -> None:  # noqa: ARG001
    raise KeyboardInterrupt


@dataclass
class _Running:
    job: Job
    process: mp.process.BaseProcess
    conn: Connection
    slot: int
    starts: int


def run_local(jobs: list[Job], stage_options: dict[str, Any], workers: int, retries: int,
              started: Callable[[Job, int], None], ended: Callable[[Job, Outcome], None],
              retrying: Callable[[Job, str], None]) -> None:
    """Run ``jobs`` on ``workers`` processes; callbacks report starts (job, pid), outcomes, retries."""
    ctx = mp.get_context("spawn")
    shares = core_shares(workers)
    queue: deque[tuple[Job, int]] = deque((j, 1) for j in jobs)
    free = list(range(workers))
    running: dict[int, _Running] = {}   # process sentinel -> running job
    try:
        while queue or running:
            while queue and free:
                job, starts = queue.popleft()
                slot = free.pop(0)
                recv, send = ctx.Pipe(duplex=False)
                proc = ctx.Process(target=_child, args=(job, stage_options, shares[slot], send),
                                   name=f"artgs-batch-{job.name}", daemon=True)
                proc.start()
                send.close()
                running[proc.sentinel] = _Running(job, proc, recv, slot, starts)
                started(job, proc.pid or 0)
            for sentinel in wait(list(running), timeout=1.0):
                r = running.pop(sentinel)
                outcome = _outcome(r)
                r.process.join()
                free.append(r.slot)
                if outcome is not None:
                    ended(r.job, outcome)
                elif r.starts <= retries:
                    retrying(r.job, _death(r.process.exitcode))
                    queue.appendleft((r.job, r.starts + 1))
                else:
                    ended(r.job, Outcome("died", f"{_death(r.process.exitcode)}; gave up after "
                                                 f"{r.starts} attempts", attempt=r.starts))
    except KeyboardInterrupt:
        _stop(list(running.values()))
        raise


def _outcome(r: _Running) -> Outcome | None:
    try:
        return r.conn.recv() if r.conn.poll() else None
    except (EOFError, OSError):
        return None
    finally:
        r.conn.close()


def _death(exitcode: int | None) -> str:
    if exitcode is not None and exitcode < 0:
        try:
            return f"worker killed by {signal.Signals(-exitcode).name}"
        except ValueError:
            return f"worker killed by signal {-exitcode}"
    return f"worker exited with status {exitcode} without a result"


def _stop(running: list[_Running]) -> None:
    """SIGTERM every worker, give them STOP_GRACE seconds, then kill what is left."""
    for r in running:
        if r.process.is_alive():
            r.process.terminate()
    for r in running:
        r.process.join(STOP_GRACE)
        if r.process.is_alive():
            r.process.kill()
            r.process.join()
