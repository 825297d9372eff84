"""The thread counts of the renderer's two runtimes, torch and numba, set together."""

from __future__ import annotations

from contextlib import contextmanager
from typing import Iterator

import numba
import torch


def set_threads(n: int) -> None:
    """torch and numba with ``n`` threads (at least one). numba first: its first call starts
    its OpenMP threads, which sets the OpenMP thread count that torch shares back to all the
    cores (seen: a spawned helper asked for one thread ran torch with two)."""
    numba.set_num_threads(max(min(n, numba.config.NUMBA_NUM_THREADS), 1))
    if torch.get_num_threads() != max(n, 1):
        torch.set_num_threads(max(n, 1))


@contextmanager
def threads(n: int) -> Iterator[None]:
    """torch and numba with ``n`` threads (at least one) for the duration."""
    before = torch.get_num_threads(), numba.get_num_threads()
    set_threads(n)
    try:
        yield
    finally:
        numba.set_num_threads(before[1])
        torch.set_num_threads(before[0])
