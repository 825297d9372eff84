"""A second process for the type choice's two independent fits (:func:`.hypotheses.select_types`).

The optimisation's work is one thread's Python and torch dispatch on small images: a second
thread in the kernels buys 13-19 % (README, *Threads*), while two one-thread processes do two
fits at once. The type choice fits each joint as the other type and restarted as its own type
(probes and a full fit each, about half of a run), each from the same model state, so one of the
two runs in a helper process (``multiprocessing.Pool``, spawned: numba's OpenMP threads do not
survive a fork) and the other here, each with half the threads.

Same result as one process: the helper gets the model's state and the random generator's, this
process skips the draws the helper's fit makes (:func:`.fit.skip_draws`), and a render's
gradients do not depend on the thread count (core/render/cpu/backend.py, ``grad_buffers``).
Used only where this process has two or more threads (``artgs batch --workers 2`` gives each
capture one); a helper that fails to start leaves everything to this process.
"""

from __future__ import annotations

import multiprocessing
import pickle
import signal
import sys
from contextlib import contextmanager
from typing import Any, Callable, Iterator

import numba
import torch

from ...model.progress import Progress

_RUN: Any = None      # the helper's copy of the Runner (set by _start)
#: Seconds between cancel checks while this process waits for the helper.
POLL = 0.2
#: Seconds a helper may take to start (import torch, load the kernels, unpickle the splat).
START_TIMEOUT = 120.0


def _start(threads: int) -> None:
    """Helper process initializer: its threads and deterministic kernels."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)      # the parent cancels and ends the helper
    torch.set_num_threads(threads)
    numba.set_num_threads(min(threads, numba.config.NUMBA_NUM_THREADS))
    torch.use_deterministic_algorithms(True, warn_only=True)


def _load(payload: bytes) -> bool:
    """The helper's first task: the Runner rebuilt from the parent's."""
    global _RUN
    from .stage import Runner
    model, frames, cfg, options, trust, space = pickle.loads(payload)
    _RUN = Runner(model, frames, cfg, Progress("quiet"), options, trust)
    _RUN.space = space
    return True


def _call(fn: Callable, blob: bytes) -> bytes:
    """Helper side of :meth:`Helper.call`: ``fn(run, *args)`` from the parent's model and
    generator state. Plain pickles both ways (tensors by value, not in shared memory)."""
    state, rng_state, args = pickle.loads(blob)
    _RUN.model.set_state(state)
    _RUN.rng.bit_generator.state = rng_state
    return pickle.dumps(fn(_RUN, *args))


class Helper:
    """One spawned helper process holding a copy of the optimisation (:class:`.stage.Runner`)
    as it was when started; each call brings it the current model state."""

    def __init__(self, run) -> None:
        m = run.model
        payload = pickle.dumps((m, run.frames, run.cfg, run.options, run.trust, run.space))
        self.threads = max(torch.get_num_threads() // 2, 1)
        with main_hidden():
            self.pool = multiprocessing.get_context("spawn").Pool(
                1, initializer=_start, initargs=(self.threads,))
        # queued: the pool's own thread sends it while this one goes on with the first fit
        self.loaded = self.pool.apply_async(_load, (payload,))
        self.worker = self._workers()
        self.checked = False

    def _workers(self) -> list[int]:
        """The pool's worker pids: a worker that died (killed, out of memory) is replaced by
        one without the run's copy, and its job never finishes."""
        return [p.pid for p in self.pool._pool]   # noqa: SLF001 - Pool has no public accessor

    def alive(self) -> bool:
        """Whether the helper started at first is still the pool's worker."""
        return self._workers() == self.worker and all(p.is_alive() for p in self.pool._pool)

    def ready(self) -> bool:
        """Wait until the helper has its copy of the run; False when it does not within the
        timeout or dies (a helper whose start fails is started again and again by the pool)."""
        if not self.checked:
            waited = 0.0
            while not self.loaded.ready() and self.alive() and waited < START_TIMEOUT:
                self.loaded.wait(POLL)
                waited += POLL
            self.checked = (self.loaded.ready() and self.loaded.successful()
                            and bool(self.loaded.get()))
        return self.checked

    def call(self, run, fn: Callable, args: tuple, here: Callable[[], Any]) -> tuple[Any, Any]:
        """``fn(run, *args)`` in the helper from the current model and generator state while
        ``here()`` runs in this process with the other threads; both results. Cancels
        (Ctrl-C, the add-on) are checked while waiting. Should the helper die, its call is
        made here afterwards, from the same state (the same result, later), and the helper is
        not used again."""
        run.processes = 2
        start = run.rng.bit_generator.state
        blob = pickle.dumps((run.model.state(), start, args))
        job = self.pool.apply_async(_call, (fn, blob))
        with threads(torch.get_num_threads() - self.threads):
            mine = here()
            while not job.ready() and self.alive():
                run.progress.check_cancel()
                job.wait(POLL)
        if job.ready() and job.successful():
            return pickle.loads(job.get()), mine
        run.progress.log("optimise: the helper process ended; this one goes on alone",
                         level="warning")
        end = run.rng.bit_generator.state
        run.rng.bit_generator.state = start
        theirs = fn(run, *args)
        run.rng.bit_generator.state = end
        stop(run)
        return theirs, mine

    def close(self) -> None:
        self.pool.terminate()
        self.pool.join()


@contextmanager
def main_hidden() -> Iterator[None]:
    """Spawn without the main module: a spawned process runs the parent's ``__main__`` again
    (as ``__mp_main__``), and a user's script that calls the optimisation without an
    ``if __name__ == "__main__"`` guard would run a second time in the helper. The helper needs
    nothing from it (only this package's functions and data are sent)."""
    main = sys.modules["__main__"]
    saved = {k: vars(main)[k] for k in ("__file__", "__spec__") if k in vars(main)}
    for k in saved:      # spawn reads __spec__'s name, else __file__
        if k == "__spec__":
            main.__spec__ = None
        else:
            del main.__file__
    try:
        yield
    finally:
        for k, v in saved.items():
            setattr(main, k, v)


@contextmanager
def threads(n: int) -> Iterator[None]:
    """torch and numba with ``n`` threads (at least one) for the duration."""
    before = torch.get_num_threads(), numba.get_num_threads()
    torch.set_num_threads(max(n, 1))
    numba.set_num_threads(max(min(n, numba.config.NUMBA_NUM_THREADS), 1))
    try:
        yield
    finally:
        torch.set_num_threads(before[0])
        numba.set_num_threads(before[1])


def start(run) -> None:
    """Start the run's helper in the background when it would pay: asked for (``helper``), CPU
    tensors, two or more threads here. Its start overlaps the first fit."""
    if (run.options.helper and run.model.axes.device.type == "cpu"
            and torch.get_num_threads() >= 2):
        try:
            run.helper = Helper(run)
        except Exception as exc:   # noqa: BLE001 - any failure: one process does all
            run.progress.log(f"optimise: no helper process ({exc}); one process fits all",
                             level="warning")


def helper(run) -> Helper | None:
    """The run's helper once it has started, else None (then this process fits all)."""
    h = run.helper
    if h is None:
        return None
    if not h.ready():
        run.progress.log("optimise: the helper process did not start; one process fits all",
                         level="warning")
        stop(run)
        return None
    return h


def stop(run) -> None:
    """End the run's helper, if any."""
    if run.helper is not None:
        run.helper.close()
        run.helper = None
