"""One capture in a worker process: thread limits, its log file, the pipeline, an outcome.

Runs in a local pool process (:mod:`.local`) or a Ray worker (:mod:`.ray_pool`). A capture's own
errors (bad input, a stage that fails) come back as an outcome with the message, never as an
exception, so that one bad capture cannot stop the batch; only a dying process is retried.
"""

from __future__ import annotations

import os
import socket
import sys
import time
import traceback
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Iterator, TextIO

from ..model.errors import ArtgsError, Cancelled, InputError
from ..model.progress import Progress
from .jobs import Job

ATTEMPT_MARK = "=== artgs batch attempt"
THREAD_VARS = ("OMP_NUM_THREADS", "MKL_NUM_THREADS", "OPENBLAS_NUM_THREADS", "NUMBA_NUM_THREADS")


@dataclass
class Outcome:
    """How one attempt at a capture ended (``status``: ok, failed, cancelled)."""

    status: str
    message: str = ""
    seconds: float = 0.0
    attempt: int = 1
    pid: int = 0
    host: str = ""
    threads: int = 0


def limit_threads_env(threads: int) -> None:
    """Set the thread-count variables torch, BLAS and numba read when first imported."""
    for var in THREAD_VARS:
        os.environ[var] = str(threads)
    # torch's OpenMP threads busy-wait between ops and starve numba's (see core/cli/main.py).
    os.environ.setdefault("OMP_WAIT_POLICY", "PASSIVE")


@contextmanager
def redirected(log: Path) -> Iterator[TextIO]:
    """Send this process's stdout and stderr (also C-level writes) to ``log`` (appended)."""
    log.parent.mkdir(parents=True, exist_ok=True)
    sys.stdout.flush()
    sys.stderr.flush()
    saved = os.dup(1), os.dup(2)
    with open(log, "a", encoding="utf-8", buffering=1) as stream:
        os.dup2(stream.fileno(), 1)
        os.dup2(stream.fileno(), 2)
        try:
            yield stream
        finally:
            stream.flush()
            sys.stdout.flush()
            sys.stderr.flush()
            os.dup2(saved[0], 1)
            os.dup2(saved[1], 2)
            os.close(saved[0])
            os.close(saved[1])


def _attempt_number(log: Path) -> int:
    """Attempts already logged for this capture in this batch run (the driver starts the log)."""
    try:
        return log.read_text(encoding="utf-8", errors="replace").count(ATTEMPT_MARK)
    except FileNotFoundError:
        return 0


def run_job(job: Job, stage_options: dict[str, Any], threads: int) -> Outcome:
    """Run the pipeline on ``job`` with ``threads`` threads; the outcome, never an exception.

    ``stage_options``: per stage name, its options dataclass (as :func:`core.pipeline.run`).
    """
    from .. import pipeline
    from ..render.threads import set_threads

    attempt = _attempt_number(job.log) + 1
    start = time.perf_counter()
    outcome = Outcome("ok", attempt=attempt, pid=os.getpid(), host=socket.gethostname(),
                      threads=threads)
    with redirected(job.log) as stream:
        stream.write(f"{ATTEMPT_MARK} {attempt}, pid {os.getpid()}, host {outcome.host}, "
                     f"{threads} thread(s), {time.strftime('%Y-%m-%dT%H:%M:%S%z')} ===\n")
        stream.write(f"capture {job.capture}\nout {job.out}\n")
        try:
            set_threads(threads)      # torch's and numba's, in this running process
            progress = Progress("text", stream=stream, min_interval=5.0)
            pipeline.run(job.capture, job.out, progress, stage_options, resume=job.resume)
        except (KeyboardInterrupt, Cancelled):
            outcome.status, outcome.message = "cancelled", "cancelled"
        except InputError as exc:
            outcome.status, outcome.message = "failed", f"bad input: {exc}"
        except ArtgsError as exc:
            outcome.status, outcome.message = "failed", str(exc)
        except Exception as exc:  # noqa: BLE001 - one capture's bug must not stop the batch
            traceback.print_exc(file=stream)
            outcome.status, outcome.message = "failed", f"{type(exc).__name__}: {exc}"
        outcome.seconds = round(time.perf_counter() - start, 2)
        stream.write(f"=== {outcome.status} in {outcome.seconds:.1f} s"
                     f"{': ' + outcome.message if outcome.message else ''} ===\n")
    return outcome
