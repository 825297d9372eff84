"""Python interpreters on this machine, found where a user's machine has them.

Used by `make test` (a Python 3.13 for the bpy 5.x half) and by the add-on's "Set Up Engine" (a
Python the engine supports). Standard library only: safe in Blender's process. Looked for, in this
order: ``python3.X``/``python3``/``python`` on PATH, pyenv's versions (``$PYENV_ROOT``, else
``~/.pyenv``; also pyenv-win), the Windows ``py`` launcher (``py -0p``), uv-managed Pythons, and
the usual install folders (Homebrew, python.org framework builds, ``%LOCALAPPDATA%\\Programs``).
Every candidate is run once to read its version: a pyenv shim that is not active, or a broken
link, is not counted.
"""

from __future__ import annotations

import os
import re
import shutil
import subprocess
import sys
from dataclasses import dataclass
from pathlib import Path

#: Minor versions looked for by name (python3.11 ... python3.15).
_MINORS = range(11, 16)
_PROBE = "import sys; print('%d.%d.%d' % sys.version_info[:3]); print(sys.executable)"
#: A minor version written in a path: python3.13, Python313, versions/3.13.0, cpython-3.13.0-...
_NAMED = re.compile(r"(?:python3\.|Python3|versions[/\\]3\.|cpython-3\.)(\d+)", re.IGNORECASE)


@dataclass(frozen=True)
class Interpreter:
    """A Python that ran: its own ``sys.executable`` (not a shim's path) and version."""

    path: str
    version: tuple[int, int, int]

    @property
    def label(self) -> str:
        return f"Python {'.'.join(map(str, self.version))} ({self.path})"


def parse_requires(spec: str) -> tuple[tuple[int, ...], tuple[int, ...] | None]:
    """``">=3.11,<3.12"`` (pyproject's requires-python; only ``>=`` and ``<`` clauses) ->
    ``((3, 11), (3, 12))``; no lower bound is (3,), no upper bound None."""
    low: tuple[int, ...] = (3,)
    high: tuple[int, ...] | None = None
    for clause in filter(None, (c.strip() for c in spec.split(","))):
        m = re.fullmatch(r"(>=|<)\s*(\d+(?:\.\d+)*)", clause)
        if m is None:
            raise ValueError(f"requires-python clause {clause!r}: only '>=X.Y' and '<X.Y' are "
                             "understood")
        version = tuple(int(p) for p in m.group(2).split("."))
        if m.group(1) == ">=":
            low = version
        else:
            high = version
    return low, high


def matches(version: tuple[int, int, int], low: tuple[int, ...],
            high: tuple[int, ...] | None = None) -> bool:
    """``low <= version < high`` (tuples compare by their leading parts)."""
    return version[:len(low)] >= low and (high is None or version[:len(high)] < high)


def probe(path: str | Path, timeout: float = 15.0) -> Interpreter | None:
    """The interpreter at ``path`` if it runs, else None."""
    try:
        proc = subprocess.run([str(path), "-c", _PROBE], capture_output=True, text=True,
                              timeout=timeout, stdin=subprocess.DEVNULL,
                              creationflags=getattr(subprocess, "CREATE_NO_WINDOW", 0))
    except (OSError, subprocess.SubprocessError):
        return None
    lines = proc.stdout.strip().splitlines()
    m = re.fullmatch(r"(\d+)\.(\d+)\.(\d+)", lines[0]) if lines else None
    if proc.returncode != 0 or m is None:
        return None
    executable = lines[1] if len(lines) > 1 and lines[1] else str(path)  # through shims
    return Interpreter(executable, tuple(int(g) for g in m.groups()))


def _named_minor(path: str) -> int | None:
    """The minor version a path names (``.../python3.13``), if it names one."""
    m = _NAMED.search(path)
    return int(m.group(1)) if m else None


def candidates() -> list[str]:
    """Paths that may be Python interpreters, most specific first (not yet run)."""
    found: list[str] = []
    for name in [f"python3.{m}" for m in reversed(_MINORS)] + ["python3", "python"]:
        path = shutil.which(name)
        if path:
            found.append(path)
    home = Path.home()
    roots = [Path(os.environ["PYENV_ROOT"])] if os.environ.get("PYENV_ROOT") else []
    roots += [home / ".pyenv", home / ".pyenv" / "pyenv-win"]
    for root in roots:
        for version in sorted((root / "versions").glob("3.*"), reverse=True):
            found += [str(version / "bin" / "python3"), str(version / "python.exe")]
    found += _py_launcher()
    uv = Path(os.environ.get("UV_PYTHON_INSTALL_DIR", "")) if os.environ.get(
        "UV_PYTHON_INSTALL_DIR") else (home / ".local" / "share" / "uv" / "python")
    for version in sorted(uv.glob("cpython-3.*"), reverse=True):
        found += [str(version / "bin" / "python3"), str(version / "python.exe")]
    for minor in reversed(_MINORS):
        found += [f"/opt/homebrew/bin/python3.{minor}", f"/usr/local/bin/python3.{minor}",
                  f"/usr/bin/python3.{minor}",
                  f"/Library/Frameworks/Python.framework/Versions/3.{minor}/bin/python3.{minor}"]
        local = os.environ.get("LOCALAPPDATA")
        if local:
            found.append(str(Path(local) / "Programs" / "Python" / f"Python3{minor}" / "python.exe"))
    return [p for p in found if Path(p).is_file()]


def _py_launcher() -> list[str]:
    """Interpreters the Windows ``py`` launcher knows (``py -0p``)."""
    py = shutil.which("py") if sys.platform == "win32" else None
    if py is None:
        return []
    try:
        out = subprocess.run([py, "-0p"], capture_output=True, text=True, timeout=15).stdout
    except (OSError, subprocess.SubprocessError):
        return []
    return [line.split()[-1] for line in out.splitlines() if line.strip().endswith(".exe")]


def find(low: tuple[int, ...], high: tuple[int, ...] | None = None,
         extra: list[str] = ()) -> list[Interpreter]:
    """Interpreters with ``low <= version < high``: ``extra`` paths first, then ``candidates()``,
    each real interpreter once."""
    seen: set[str] = set()
    result = []
    for path in [*extra, *candidates()]:
        real = os.path.realpath(path)
        minor = _named_minor(real)
        if real in seen or (minor is not None and not matches((3, minor, 0), low[:2], high)):
            continue
        seen.add(real)
        interpreter = probe(path)
        if interpreter is None or not matches(interpreter.version, low, high):
            continue
        real = os.path.realpath(interpreter.path)
        if real != os.path.realpath(path) and real in seen:
            continue
        seen.add(real)
        result.append(interpreter)
    return result


WHERE = ("python3.X on PATH, pyenv's versions, the py launcher (Windows), uv's Pythons and the "
         "usual install folders")
