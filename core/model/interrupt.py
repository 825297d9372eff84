"""Ctrl-C and SIGTERM: remembered in a flag, so a cancel is recognised whatever it turned into.

The signal handler sets the flag and raises KeyboardInterrupt at once. Raised inside a C
extension's callback (a numba kernel, torch's autograd engine calling a custom backward), the
KeyboardInterrupt can come out as a ``SystemError`` ("returned a result with an exception set")
or a ``RuntimeError``; with the flag set, :func:`interrupted` still says it was a cancel, and
``Progress.check_cancel`` stops at the next checkpoint if the interrupt was swallowed.
"""

from __future__ import annotations

import functools
import signal
import threading
from contextlib import contextmanager
from typing import Callable, Iterator, TypeVar

from .errors import Cancelled

_requested = threading.Event()
F = TypeVar("F", bound=Callable)


def request_cancel() -> None:
    """Ask the running command to stop."""
    _requested.set()


def cancel_requested() -> bool:
    """Whether Ctrl-C/SIGTERM arrived (or :func:`request_cancel` was called)."""
    return _requested.is_set()


def interrupted(exc: BaseException) -> bool:
    """Whether ``exc`` is, or was caused by, a cancel."""
    seen: set[int] = set()
    e: BaseException | None = exc
    while e is not None and id(e) not in seen:
        if isinstance(e, (KeyboardInterrupt, Cancelled)):
            return True
        seen.add(id(e))
        e = e.__cause__ or e.__context__
    return cancel_requested()


def _on_signal(signum, frame) -> None:  # noqa: ARG001
    request_cancel()
    raise KeyboardInterrupt


@contextmanager
def cancel_on_signals() -> Iterator[None]:
    """Ctrl-C (SIGINT) and SIGTERM cancel the command inside the ``with`` body (main thread
    only; elsewhere signals keep their handlers); the previous handlers are restored after."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    previous = {s: signal.getsignal(s) for s in (signal.SIGINT, signal.SIGTERM)}
    for s in previous:
        signal.signal(s, _on_signal)
    try:
        yield
    finally:
        for s, handler in previous.items():
            signal.signal(s, handler)


def ignore_further_interrupts() -> None:
    """From now on Ctrl-C/SIGTERM only set the flag (while the command reports and exits)."""
    signal.signal(signal.SIGINT, lambda signum, frame: request_cancel())
    signal.signal(signal.SIGTERM, lambda signum, frame: request_cancel())


def cancellable(func: F) -> F:
    """Re-raise whatever ``func`` raises after a cancel as :class:`Cancelled`."""
    @functools.wraps(func)
    def wrapper(*args, **kwargs):
        try:
            return func(*args, **kwargs)
        except Exception as exc:
            if interrupted(exc):
                raise Cancelled("cancelled") from None
            raise
    return wrapper  # type: ignore[return-value]
