"""``kernel``: numba's ``njit`` with an on-disk cache that is keyed on the image-model constants.

numba freezes the module globals a kernel reads (core/render/constants.py values, the tile size)
into the compiled code, but its cache checks only the kernel's own source file and bytecode: after
a constant changed, ``njit(cache=True)`` would keep loading the kernel compiled with the old
value. Here every cache file name and index stamp also carries :func:`cache_key`, a hash of the
constants' values and of the kernel modules' sources (kernels call across them), so a change
compiles afresh and switching back finds the earlier files again.

This uses numba's documented cache-locator classes (``numba.core.caching``, numba pinned in
pyproject.toml) rather than a fork of the kernels with the constants as arguments, which would cost
the constant folding in the inner loops.
"""

from __future__ import annotations

import hashlib
from pathlib import Path
from typing import Any, Callable

import numba
from numba.core.caching import CompileResultCacheImpl, FunctionCache

from .. import constants

_KERNEL_SOURCES = ("blend_kernels.py", "project_kernels.py", "jit.py")

#: The fast-math flags of every kernel that asks for ``fastmath=True``: LLVM's ``fast`` set
#: without ``contract`` (fusing a multiply and an add into one FMA). With contraction the code
#: numba's JIT runs and the object code it writes to the cache fuse differently, so a process that
#: compiled the kernels computed other numbers than one that loaded them: depth 4e-5 and
#: gradients 2e-3 apart on one render, and a PartNet capture's splat and proposals differed
#: between a fresh clone and the next run. Without it both agree to the bit, at the same speed.
FASTMATH = frozenset({"nnan", "ninf", "nsz", "arcp", "afn", "reassoc"})


def cache_key() -> str:
    """Hex digest of the current constants (every upper-case name of core/render/constants.py) and
    of the kernel modules' and this module's source."""
    h = hashlib.sha256()
    values = sorted((k, repr(v)) for k, v in vars(constants).items() if k.isupper())
    h.update(repr(values).encode())
    here = Path(__file__).parent
    for name in _KERNEL_SOURCES:
        h.update((here / name).read_bytes())
    return h.hexdigest()[:16]


def _keyed_cache(key: str) -> type[FunctionCache]:
    """A numba function cache whose locators add ``key`` to the file names and source stamp."""

    class Keyed:
        def get_source_stamp(self) -> Any:
            return (super().get_source_stamp(), key)  # type: ignore[misc]

        def get_disambiguator(self) -> str:
            return f"{super().get_disambiguator()}-{key}"  # type: ignore[misc]

    class Impl(CompileResultCacheImpl):
        _locator_classes = [type(f"Keyed{c.__name__}", (Keyed, c), {})
                            for c in CompileResultCacheImpl._locator_classes]

    class Cache(FunctionCache):
        _impl_class = Impl

    return Cache


def kernel(fn: Callable | None = None, **options: Any):
    """``numba.njit(**options)`` cached on disk under :func:`cache_key` (use as ``@kernel`` or
    ``@kernel(parallel=True, ...)``); ``fastmath=True`` means :data:`FASTMATH`."""
    if options.get("fastmath") is True:
        options["fastmath"] = set(FASTMATH)

    def wrap(f: Callable):
        dispatcher = numba.njit(**options)(f)
        dispatcher._cache = _keyed_cache(cache_key())(dispatcher.py_func)
        return dispatcher
    return wrap(fn) if fn is not None else wrap
