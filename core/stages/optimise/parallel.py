"""A second process for the optimisation: the type choice's two independent fits
(:func:`.hypotheses.select_types`), the second half of every other fit step's frames, and half
of the frames of long evaluations.

The optimisation's work is one thread's Python and torch dispatch on small images: a second thread
in the kernels buys 13-19 % (docs/benchmark-log.md, *Threads*), while two one-thread processes do
two things at once. The type choice fits each joint as the other type and restarted as its own type
(probes and a full fit each, about half of a run), each from the same model state, so one of the
two runs in a helper process (spawned: numba's OpenMP threads do not survive a fork; :func:`spawn`)
and the other here, each with half the threads. Every other fit renders a step's second half of
frames (one of two cameras) there while this process renders the first (:class:`Halves`,
:func:`.fit.halves`); the gradients are summed here. :func:`evaluate` splits its frames the same
way.

Same result as one process: the helper gets the model's state and the random generator's, this
process skips the draws the helper's fit makes (:func:`.fit.skip_draws`), one process renders
a step's halves apart too and sums their gradients in the same order, and a render's
gradients do not depend on the thread count (core/render/cpu/backend.py, ``grad_buffers``).
Used only where this process has two or more threads (``artgs batch --workers 2`` gives each
capture one); a helper that fails to start leaves everything to this process"""

from __future__ import annotations

import multiprocessing
import pickle
import signal
import sys
import threading
from contextlib import contextmanager
from multiprocessing.connection import Connection
from multiprocessing.process import BaseProcess
from typing import Any, Callable, Iterator

import numpy as np
import torch

from ...model.progress import Progress
from ...render.threads import set_threads, threads
from .fit import evaluate as evaluate_here, half_grads, here

_RUN: Any = None      # the helper's copy of the Runner (set by _load)
#: Seconds between cancel checks while this process waits for the helper.
POLL = 0.2
#: Seconds a helper may take to start (import torch, load the kernels, unpickle the splat).
START_TIMEOUT = 120.0


def _serve(conn: Connection, threads: int) -> None:
    """The helper process: each request ``(fn, args)`` it receives is run as ``fn(*args)`` and
    answered with ``(True, result)`` or ``(False, error)``, in order, until the pipe closes.
    Plain pickles both ways (tensors by value, not in shared memory)."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)      # the parent cancels and ends the helper
    set_threads(threads)
    torch.use_deterministic_algorithms(True, warn_only=True)
    while True:
        try:
            fn, args = pickle.loads(conn.recv_bytes())
        except (EOFError, OSError):
            return
        try:
            reply = (True, fn(*args))
        except Exception as exc:   # noqa: BLE001 - reported to the parent, which goes on alone
            reply = (False, f"{type(exc).__name__}: {exc}")
        conn.send_bytes(pickle.dumps(reply))


def spawn(threads: int) -> tuple[BaseProcess, Connection]:
    """A helper process with ``threads`` threads serving requests (:func:`_serve`) on the
    returned connection. A process and a pipe, not a ``multiprocessing.Pool``: a pool's worker
    killed while it reads its task queue holds the queue's lock for ever, and the pool's
    ``terminate`` then waits for it (seen: a helper killed mid-fit hung the run)."""
    ctx = multiprocessing.get_context("spawn")
    mine, theirs = ctx.Pipe()
    proc = ctx.Process(target=_serve, args=(theirs, threads), daemon=True, name="artgs-helper")
    with main_hidden():
        proc.start()
    theirs.close()
    return proc, mine


def _load(payload: bytes) -> bool:
    """The helper's first request: the Runner rebuilt from the parent's."""
    global _RUN
    from .stage import Runner
    model, frames, cfg, options, trust, space = pickle.loads(payload)
    _RUN = Runner(model, frames, cfg, Progress("quiet"), options, trust)
    _RUN.space = space
    return True


def _call(fn: Callable, state: dict, rng_state: dict, args: tuple) -> Any:
    """Helper side of :meth:`Helper.call`: ``fn(run, *args)`` from the parent's model and
    generator state."""
    _RUN.model.set_state(state)
    _RUN.rng.bit_generator.state = rng_state
    return fn(_RUN, *args)


def _begin(state: dict) -> None:
    """Helper side of :class:`Halves`: the model's state at a fit's start."""
    _RUN.model.set_state(state)


def _half(params: dict, level: int, widen: float, ids: list[int], n: int) -> tuple:
    """Helper side of :class:`Halves`: :func:`.fit.half_grads` at the parent's parameters."""
    leaves = {k: v.requires_grad_(True) for k, v in params.items()}
    return half_grads(_RUN.model, _RUN.frames, _RUN.cfg, leaves, level, widen, ids, n)


def losses_of(run, level: int, ids: list[int]) -> np.ndarray:
    """:func:`.fit.evaluate` of ``run``'s model on frames ``ids`` at ``level`` (either side of
    :func:`evaluate`)."""
    return evaluate_here(run.model, run.frames, run.cfg, level, ids)


class Helper:
    """One spawned helper process holding a copy of the optimisation (:class:`.stage.Runner`)
    as it was when started; each request brings it the current model state. Requests are
    numbered and answered in order."""

    def __init__(self, run) -> None:
        payload = pickle.dumps((run.model, run.frames, run.cfg, run.options, run.trust,
                                run.space))
        self.threads = max(torch.get_num_threads() // 2, 1)
        self.proc, self.conn = spawn(self.threads)
        self.sent = self.received = 0
        self.replies: dict[int, tuple[bool, Any]] = {}
        self.unwanted: set[int] = set()
        self.sending: threading.Thread | None = None
        # sent by a thread while this one goes on with the first fit (the helper reads it
        # once it has imported torch)
        self.loaded = self.submit(_load, (payload,), background=True)
        self.up: bool | None = None     # whether it loaded the run; None: not known yet
        self.busy = False      # in :meth:`call`: its fits here render all their frames here

    def submit(self, fn: Callable, args: tuple, wanted: bool = True,
               background: bool = False) -> int:
        """Send the request ``fn(*args)``; returns its number (for :meth:`reply`)."""
        if self.sending is not None:
            self.sending.join()
            self.sending = None
        blob = pickle.dumps((fn, args))
        if background:
            self.sending = threading.Thread(target=self._send, args=(blob,), daemon=True)
            self.sending.start()
        else:
            self._send(blob)
        job = self.sent
        self.sent += 1
        if not wanted:
            self.unwanted.add(job)
        return job

    def _send(self, blob: bytes) -> None:
        try:
            self.conn.send_bytes(blob)
        except (OSError, ValueError):     # a dead helper: its reply never comes (:meth:`reply`)
            pass

    def _take(self, timeout: float) -> bool:
        """Take one reply if one arrives within ``timeout`` s; False when none did. Raises
        EOFError or OSError when the helper has gone."""
        if not self.conn.poll(timeout):
            return False
        reply = pickle.loads(self.conn.recv_bytes())
        if self.received in self.unwanted:
            self.unwanted.discard(self.received)
        else:
            self.replies[self.received] = reply
        self.received += 1
        return True

    def reply(self, job: int, check: Callable[[], None] | None = None,
              timeout: float | None = None) -> tuple[bool, Any]:
        """Wait for request ``job``'s reply: ``(True, result)``, or ``(False, why)`` when it
        failed, the helper ended, or ``timeout`` s passed. ``check()`` (cancel) is called
        while waiting."""
        waited = 0.0
        while job not in self.replies:
            try:
                if not self._take(POLL) and not self.proc.is_alive():
                    return False, "the helper process ended"
            except (EOFError, OSError):
                return False, "the helper process ended"
            waited += POLL
            if timeout is not None and waited >= timeout and job not in self.replies:
                return False, f"the helper process did not answer within {timeout:.0f} s"
            if check is not None:
                check()
        return self.replies.pop(job)

    def started(self) -> bool:
        """Whether the helper has its copy of the run now (no waiting) and is alive."""
        if self.up is None:
            try:
                while self._take(0.0):
                    pass
            except (EOFError, OSError):
                self.up = False
            if self.loaded in self.replies:
                ok, value = self.replies.pop(self.loaded)
                self.up = ok and bool(value)
        return bool(self.up) and self.proc.is_alive()

    def ready(self) -> bool:
        """Wait until the helper has its copy of the run; False when it does not within the
        timeout or fails."""
        if self.up is None:
            ok, value = self.reply(self.loaded, timeout=START_TIMEOUT)
            self.up = ok and bool(value)
        return self.up

    def call(self, run, fn: Callable, args: tuple, here: Callable[[], Any]) -> tuple[Any, Any]:
        """``fn(run, *args)`` in the helper from the current model and generator state while
        ``here()`` runs in this process with the other threads; both results. Cancels
        (Ctrl-C, the add-on) are checked while waiting. Should the helper fail or die, its
        call is made here afterwards, from the same state (the same result, later), and the
        helper is not used again."""
        run.processes = 2
        start = run.rng.bit_generator.state
        job = self.submit(_call, (fn, run.model.state(), start, args))
        self.busy = True
        try:
            with threads(torch.get_num_threads() - self.threads):
                mine = here()
                ok, theirs = self.reply(job, run.progress.check_cancel)
        finally:
            self.busy = False
        if ok:
            return theirs, mine
        ended(run, theirs)
        end = run.rng.bit_generator.state
        run.rng.bit_generator.state = start
        theirs = fn(run, *args)
        run.rng.bit_generator.state = end
        return theirs, mine

    def close(self) -> None:
        """End the helper process (first: a request being sent then fails, and its thread
        ends)."""
        self.proc.terminate()
        self.proc.join(5)
        if self.proc.is_alive():
            self.proc.kill()
            self.proc.join()
        if self.sending is not None:
            self.sending.join()
        self.conn.close()


class Halves:
    """:data:`.fit.Other` through the helper: a fit step's second half of frames rendered
    there while this process renders the first, each with half the threads. Until the helper
    has started (the first fit overlaps its start), and should it die, the halves are
    rendered here with all the threads (the same result). Made per fit (:func:`other`); the
    caller restores the thread count after the fit."""

    def __init__(self, run, helper: Helper) -> None:
        self.run, self.helper = run, helper
        self.local = here(run.model, run.frames, run.cfg)
        self.all = torch.get_num_threads()
        self.begun = False

    def __call__(self, params, level, widen, ids, n):
        h = self.helper
        if self.run.helper is not h or not h.started():
            set_threads(self.all)
            return self.local(params, level, widen, ids, n)
        if not self.begun:     # the fit's model (parts, types, flags) once, then its parameters
            state = {k: v.detach() if torch.is_tensor(v) else v
                     for k, v in self.run.model.state().items()}
            h.submit(_begin, (state,), wanted=False)
            self.begun = True
            self.run.processes = 2
        job = h.submit(_half, ({k: v.detach() for k, v in params.items()}, level, widen, ids, n))
        set_threads(self.all - h.threads)

        def wait():
            ok, value = h.reply(job, self.run.progress.check_cancel)
            if ok:
                return value
            ended(self.run, value)
            set_threads(self.all)
            return self.local(params, level, widen, ids, n)()
        return wait


def evaluate(run, level: int = 0, subset: list[int] | None = None) -> np.ndarray:
    """:func:`.fit.evaluate` of ``run``'s model on its frames (or ``subset``) at ``level``: the
    second half of the frames in the helper when it is there and free, the first here at once
    (each frame's loss is its own: the same values as here alone)."""
    ids = list(range(len(run.frames.time_index))) if subset is None else list(subset)
    h = run.helper
    if h is None or h.busy or len(ids) < 2 or not h.started():
        return losses_of(run, level, ids)
    cut = len(ids) // 2
    theirs, mine = h.call(run, losses_of, (level, ids[cut:]),
                          lambda: losses_of(run, level, ids[:cut]))
    return np.concatenate([mine, theirs])


def other(run) -> Halves | None:
    """Where the run's fit steps render their second halves: the helper when there is one
    and it is not fitting a hypothesis of its own (:meth:`Helper.call`), else None (here)."""
    h = run.helper
    return Halves(run, h) if h is not None and not h.busy else None


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


def ended(run, why: str) -> None:
    """The helper failed or died (killed, out of memory): say so, and go on without it."""
    run.progress.log(f"optimise: {why}; this process goes on alone", level="warning")
    stop(run)


def stop(run) -> None:
    """End the run's helper, if any."""
    if run.helper is not None:
        run.helper.close()
        run.helper = None
