"""The optimisation's routes (:data:`.stage.ROUTES`) side by side: the first in this process,
each other one in a spawned process of its own, the threads split between them (a route with
two or more has its helper, :mod:`.parallel`; on two cores neither has one).

Why: a route is one thread's Python and torch dispatch most of the time. The helper's halves
bring a route's fit steps to ~1.5x (docs/benchmark-log.md, *Fit steps and evaluations split
with the helper*: 172 -> 117 s), while whole routes side by side, sharing nothing, run at ~2x.
Used when the stage has as many threads as routes (CPU tensors, ``helper`` asked for); else one
route after the other, each with its helper.

Same result as one after the other: a route's result depends neither on its thread count nor on
a helper (:mod:`.parallel`), and each route seeds its own generators. The routes' messages are
reported as they come, each named by its route; only the first route streams its joints (the
add-on's bones follow one route, not both). A route process that fails or dies is said, and its
route then runs here afterwards (the same result, later)."""

from __future__ import annotations

import multiprocessing
import os
import pickle
import signal
import threading
from contextlib import ExitStack
from multiprocessing.connection import Connection
from multiprocessing.process import BaseProcess
from typing import Any, Callable

import torch

from ...model.errors import Cancelled
from ...model.progress import Progress
from .fit import FitConfig
from ...render.threads import set_threads, threads as parallel_threads
from .parallel import POLL, main_hidden

#: ``work(name, cfg, progress, closing, span, label)`` -> the route's result (picklable): one
#: route from the proposals (:func:`.stage._route` with the stage's inputs bound)
Work = Callable[..., Any]


class Shared:
    """The stage's progress while routes run at once: its fraction the mean of the routes'
    fractions; one writer at a time."""

    def __init__(self, progress: Progress, names: list[str]) -> None:
        self.progress = progress
        self.fractions = dict.fromkeys(names, 0.0)
        self.lock = threading.Lock()


class RouteProgress:
    """One route's view of the stage's progress (the :class:`.stage.Runner`'s ``progress``)."""

    def __init__(self, shared: Shared, name: str, live: bool) -> None:
        self.shared, self.name, self.live = shared, name, live

    def update(self, stage: str, fraction: float, message: str = "", force: bool = False,
               **figures: Any) -> None:
        s = self.shared
        if not self.live:
            figures.pop("joints", None)
        with s.lock:
            s.fractions[self.name] = fraction
            s.progress.update(stage, sum(s.fractions.values()) / len(s.fractions), message,
                              force, **figures)

    def log(self, message: str, level: str = "info") -> None:
        with self.shared.lock:
            self.shared.progress.log(f"route {self.name}: {message}", level)

    def check_cancel(self) -> None:
        self.shared.progress.check_cancel()


class Forward:
    """A route process's progress: each update and note sent to this process's parent, which
    reports them (:class:`RouteProgress`); the parent cancels by ending the process, and should
    the parent be gone (killed), the process ends itself."""

    def __init__(self, conn: Connection) -> None:
        self.conn = conn
        self.parent = os.getppid()

    def update(self, stage: str, fraction: float, message: str = "", force: bool = False,
               **figures: Any) -> None:
        self.check_cancel()
        figures.pop("joints", None)
        self.conn.send_bytes(pickle.dumps(("update", (stage, fraction, message, force), figures)))

    def log(self, message: str, level: str = "info") -> None:
        self.conn.send_bytes(pickle.dumps(("log", (message, level), {})))

    def check_cancel(self) -> None:
        """End this process if its parent has gone (else the parent ends it)."""
        if os.getppid() != self.parent:
            os._exit(1)


def _serve(conn: Connection, threads: int, payload: bytes) -> None:
    """A route process: runs ``work(name, cfg, ...)`` from ``payload`` and sends its result
    (``("done", result, {})``) or why it failed (``("failed", why, {})``); every message is
    ``(kind, args, figures)``, a plain pickle (tensors by value, as :mod:`.parallel`'s)."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)      # the parent cancels and ends it
    try:
        work, name, cfg, span = pickle.loads(payload)
        set_threads(threads)
        torch.use_deterministic_algorithms(True, warn_only=True)
        with ExitStack() as closing:
            result = work(name, cfg, Forward(conn), closing, span, name)
        reply = pickle.dumps(("done", result, {}))
    except Exception as exc:   # noqa: BLE001 - reported to the parent, which runs it itself
        reply = pickle.dumps(("failed", f"{type(exc).__name__}: {exc}", {}))
    conn.send_bytes(reply)
    conn.close()


class RouteProcess:
    """One route running in a spawned process; its messages reported by a thread here."""

    def __init__(self, work: Work, name: str, cfg: FitConfig, threads: int,
                 progress: RouteProgress) -> None:
        self.name, self.cfg, self.progress = name, cfg, progress
        ctx = multiprocessing.get_context("spawn")
        self.conn, theirs = ctx.Pipe()
        self.outcome: tuple[str, Any] = ("failed", "the route process ended")
        self.reader = threading.Thread(target=self._read, daemon=True)
        self.proc: BaseProcess = ctx.Process()    # until started
        try:
            payload = pickle.dumps((work, name, cfg, (0.0, 1.0)))
            # not a daemon, so that a route with two or more threads can have a helper
            self.proc = ctx.Process(target=_serve, args=(theirs, threads, payload),
                                    daemon=False, name=f"artgs-route-{name}")
            with main_hidden():
                self.proc.start()
        except Exception as exc:   # noqa: BLE001 - any failure: the route runs here
            self.outcome = ("failed", f"the route process did not start: {exc}")
            return
        finally:
            theirs.close()
        self.reader.start()

    def _read(self) -> None:
        """Report the process's messages until its result comes or it ends."""
        while True:
            try:
                kind, args, figures = pickle.loads(self.conn.recv_bytes())
            except (EOFError, OSError):
                return
            if kind in ("done", "failed"):
                self.outcome = (kind, args)
                return
            try:
                if kind == "update":
                    self.progress.update(*args, **figures)
                else:
                    self.progress.log(*args)
            except Cancelled:       # the main thread sees the cancel too and ends the process
                pass

    def result(self, check: Callable[[], None]) -> tuple[bool, Any]:
        """Wait for the route's result: ``(True, result)`` or ``(False, why)``; ``check()``
        (cancel) is called while waiting."""
        while self.reader.is_alive():
            self.reader.join(POLL)
            check()
        kind, value = self.outcome
        return kind == "done", value

    def close(self) -> None:
        """End the process (done or not)."""
        if self.proc.pid is None:      # never started
            self.conn.close()
            return
        self.proc.terminate()
        self.proc.join(5)
        if self.proc.is_alive():
            self.proc.kill()
            self.proc.join()
        self.conn.close()


def side_by_side(routes: list[tuple[str, FitConfig]], concurrent: bool) -> bool:
    """Whether the routes run at once: two or more, asked for (``concurrent``: CPU tensors and
    a second process allowed) and at least one thread for each."""
    return concurrent and len(routes) > 1 and torch.get_num_threads() >= len(routes)


def run_routes(work: Work, routes: list[tuple[str, FitConfig]], progress: Progress,
               concurrent: bool) -> tuple[list[Any], int]:
    """Every route's result, in the order of ``routes``, and the number of processes that ran
    them at once (1: one after the other)."""
    n = len(routes)
    if not side_by_side(routes, concurrent):
        done = []
        for i, (name, cfg) in enumerate(routes):
            with ExitStack() as closing:
                done.append(work(name, cfg, progress, closing, (i / n, 1 / n),
                                 name if n > 1 else ""))
        return done, 1
    threads = torch.get_num_threads() // n
    shared = Shared(progress, [name for name, _ in routes])
    views = [RouteProgress(shared, name, live=i == 0) for i, (name, _) in enumerate(routes)]
    with ExitStack() as closing:
        others = []
        for (name, cfg), view in zip(routes[1:], views[1:]):
            others.append(RouteProcess(work, name, cfg, threads, view))
            closing.callback(others[-1].close)
        name, cfg = routes[0]
        with ExitStack() as mine, parallel_threads(threads):
            first = work(name, cfg, views[0], mine, (0.0, 1.0), name)
        done = [first]
        for other in others:
            ok, value = other.result(progress.check_cancel)
            if not ok:
                progress.log(f"optimise: route {other.name} failed in its process ({value}); "
                             f"it runs here now", level="warning")
                with ExitStack() as again:
                    value = work(other.name, other.cfg, other.progress, again, (0.0, 1.0),
                                 other.name)
            done.append(value)
    return done, n
