"""How much memory this process may still use, to refuse work that would not fit before it starts.

The smallest of: the system's available memory (``MemAvailable`` on Linux, ``GlobalMemoryStatusEx``
on Windows, free pages elsewhere), the container's cgroup limit less its usage, and
``$ARTGS_MEMORY_LIMIT`` (bytes, or with a K/M/G suffix: for batch jobs sharing a machine) less
what this process already holds.
"""

from __future__ import annotations

import os
import re
import sys
from pathlib import Path

from .errors import InputError

ENV_LIMIT = "ARTGS_MEMORY_LIMIT"
_UNITS = {"": 1, "K": 1 << 10, "M": 1 << 20, "G": 1 << 30, "T": 1 << 40}


def parse_bytes(text: str) -> int:
    """``"1.5G"`` -> bytes; InputError naming ``$ARTGS_MEMORY_LIMIT`` when unreadable."""
    m = re.fullmatch(r"\s*([0-9]*\.?[0-9]+)\s*([KMGT]?)i?B?\s*", text, re.IGNORECASE)
    if not m:
        raise InputError(f"${ENV_LIMIT}", f"must be a size such as 4G or 512M, not {text!r}")
    return int(float(m.group(1)) * _UNITS[m.group(2).upper()])


def available_bytes() -> int | None:
    """Bytes this process can still allocate (None when the system does not say)."""
    candidates = [_system_available(), _cgroup_available()]
    limit = os.environ.get(ENV_LIMIT)
    if limit:
        candidates.append(parse_bytes(limit) - resident_bytes())
    known = [c for c in candidates if c is not None]
    return max(min(known), 0) if known else None


def resident_bytes() -> int:
    """This process's resident memory now (0 when unknown)."""
    try:
        fields = Path("/proc/self/statm").read_text().split()
        return int(fields[1]) * os.sysconf("SC_PAGE_SIZE")
    except (OSError, ValueError, IndexError, AttributeError):
        return 0


def _system_available() -> int | None:
    try:
        for line in Path("/proc/meminfo").read_text().splitlines():
            if line.startswith("MemAvailable:"):
                return int(line.split()[1]) * 1024
    except (OSError, ValueError, IndexError):
        pass
    if sys.platform == "win32":
        return _windows_available()
    try:
        return os.sysconf("SC_AVPHYS_PAGES") * os.sysconf("SC_PAGE_SIZE")
    except (OSError, ValueError, AttributeError):
        return None


def _cgroup_available() -> int | None:
    for limit_file, usage_file in (("/sys/fs/cgroup/memory.max", "/sys/fs/cgroup/memory.current"),
                                   ("/sys/fs/cgroup/memory/memory.limit_in_bytes",
                                    "/sys/fs/cgroup/memory/memory.usage_in_bytes")):
        try:
            limit = Path(limit_file).read_text().strip()
            usage = int(Path(usage_file).read_text().strip())
        except (OSError, ValueError):
            continue
        if limit.isdigit() and int(limit) < 1 << 60:   # "max" or a huge number: no limit
            return int(limit) - usage
    return None


def _windows_available() -> int | None:
    import ctypes

    class MemoryStatus(ctypes.Structure):
        _fields_ = [("dwLength", ctypes.c_ulong), ("dwMemoryLoad", ctypes.c_ulong),
                    ("ullTotalPhys", ctypes.c_ulonglong), ("ullAvailPhys", ctypes.c_ulonglong),
                    ("ullTotalPageFile", ctypes.c_ulonglong),
                    ("ullAvailPageFile", ctypes.c_ulonglong),
                    ("ullTotalVirtual", ctypes.c_ulonglong),
                    ("ullAvailVirtual", ctypes.c_ulonglong),
                    ("ullAvailExtendedVirtual", ctypes.c_ulonglong)]

    status = MemoryStatus()
    status.dwLength = ctypes.sizeof(MemoryStatus)
    if not ctypes.windll.kernel32.GlobalMemoryStatusEx(ctypes.byref(status)):
        return None
    return int(status.ullAvailPhys)


def gigabytes(n: float) -> str:
    """``n`` bytes as text in GB."""
    return f"{n / (1 << 30):.1f} GB"
