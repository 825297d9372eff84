"""Before a stage writes into OUT: the folder is usable, it is ours alone, and it is clean.

:func:`claim_out` is what the pipeline runner wraps every writing stage in: it refuses an
unusable OUT (an existing file, a path under a file, a folder it cannot write to, a malformed
``report.json``) before any work, naming the path; then creates OUT, holds its lock
(core/model/lock.py) for the stage and removes temporary files a killed run left behind.
"""

from __future__ import annotations

import os
import tempfile
from contextlib import contextmanager
from pathlib import Path
from typing import Iterator

from . import layout
from .atomic import remove_stale_temporaries
from .errors import InputError
from .lock import out_lock


def check_out(out: str | Path) -> None:
    """Refuse an output folder no stage could write to, before any work; creates nothing."""
    out = Path(out)
    if out.exists() and not out.is_dir():
        raise InputError(out, "the output folder is an existing file; give a folder path")
    existing = out
    while not existing.exists():   # nearest existing ancestor: the folder would be made in it
        if existing.parent == existing:
            break
        existing = existing.parent
    if existing != out and not existing.is_dir():
        raise InputError(out, f"cannot make the output folder: {existing} is a file, not a folder")
    _probe_writable(out, existing)
    if out.is_dir():
        layout.read_report(out)   # a malformed report.json is refused now, not after the work


def _probe_writable(out: Path, folder: Path) -> None:
    """Create and remove a scratch entry in ``folder`` (permission bits alone miss read-only
    mounts, and root ignores them)."""
    try:
        if folder == out:
            fd, probe = tempfile.mkstemp(prefix=".artgs-probe-", dir=folder)
            os.close(fd)
            os.unlink(probe)
        else:
            os.rmdir(tempfile.mkdtemp(prefix=".artgs-probe-", dir=folder))
    except OSError as exc:
        where = "the output folder" if folder == out else f"{folder}, where it would be made"
        raise InputError(out, f"cannot write to {where}: {exc.strerror or exc}") from None


@contextmanager
def claim_out(out: str | Path, command: str = "") -> Iterator[Path]:
    """Check ``out``, create it, hold its lock and clean stale temporaries for the ``with`` body."""
    out = Path(out)
    check_out(out)
    created = not out.exists()
    out.mkdir(parents=True, exist_ok=True)
    try:
        with out_lock(out, command):
            remove_stale_temporaries(out)
            yield out
    except BaseException:
        if created and not any(out.iterdir()):   # a refused first run leaves no empty folder
            out.rmdir()
        raise
