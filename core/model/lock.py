"""One run at a time per output folder: an OS file lock on ``OUT/.artgs.lock``.

The lock is the operating system's (``fcntl.flock`` on POSIX, ``msvcrt.locking`` on Windows), so
it is released when its process ends in any way, even by SIGKILL: a lock file left by a dead
process is simply taken over. The file also records the holder's pid and command, which a second
run names when it refuses.
"""

from __future__ import annotations

import json
import os
import sys
import time
from contextlib import contextmanager
from pathlib import Path
from typing import IO, Iterator

from .errors import InputError

LOCK = ".artgs.lock"
_WINDOWS_LOCK_OFFSET = 1 << 30
_held: dict[Path, int] = {}   # locks this process holds -> nesting depth (``run`` holds, stages nest)


@contextmanager
def out_lock(out: str | Path, command: str = "") -> Iterator[Path]:
    """Hold the lock on the folder ``out`` for the ``with`` body (re-entrant in one process).

    Raises :class:`InputError` naming the lock file and the holder's pid when another live
    process holds it.
    """
    path = (Path(out) / LOCK).resolve()
    if path in _held:
        _held[path] += 1
        try:
            yield path
        finally:
            _held[path] -= 1
        return
    f = _acquire(path)
    _held[path] = 1
    try:
        f.seek(0)
        f.truncate()
        f.write(json.dumps({"pid": os.getpid(), "command": command,
                            "started": time.strftime("%Y-%m-%dT%H:%M:%S%z")}) + "\n")
        f.flush()
        yield path
    finally:
        del _held[path]
        if sys.platform != "win32":   # Windows cannot remove an open file; the next run reuses it
            path.unlink(missing_ok=True)
        f.close()


def _acquire(path: Path) -> IO[str]:
    """The open, locked lock file (retries when the file was replaced while locking)."""
    while True:
        f = open(path, "a+", encoding="utf-8")
        if not _try_lock(f):
            holder = _holder(f)
            f.close()
            raise InputError(path, f"another artgs run is writing to this folder ({holder}); "
                             "wait for it to finish or use another output folder")
        try:   # the previous holder may have removed the file between our open and lock
            same = os.path.samestat(os.fstat(f.fileno()), os.stat(path))
        except FileNotFoundError:
            same = False
        if same:
            return f
        f.close()


def _try_lock(f: IO[str]) -> bool:
    try:
        if sys.platform == "win32":   # one byte far past the text, which stays readable
            import msvcrt
            f.seek(_WINDOWS_LOCK_OFFSET)
            msvcrt.locking(f.fileno(), msvcrt.LK_NBLCK, 1)
        else:
            import fcntl
            fcntl.flock(f.fileno(), fcntl.LOCK_EX | fcntl.LOCK_NB)
    except OSError:
        return False
    return True


def _holder(f: IO[str]) -> str:
    """The holder as recorded in the lock file, for the refusal message."""
    try:
        f.seek(0)
        info = json.loads(f.read() or "{}")
    except (OSError, ValueError):
        info = {}
    if not isinstance(info, dict) or "pid" not in info:
        return "its pid is not recorded yet"
    text = f"pid {info['pid']}"
    if info.get("command"):
        text += f", `{info['command']}`"
    if info.get("started"):
        text += f", started {info['started']}"
    return text
