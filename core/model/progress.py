"""Progress reporting for long stages: human text, JSON lines for the add-on, or nothing.

JSON lines (one object per line on stdout) are the worker protocol the Blender add-on reads; the
event names are in :mod:`.protocol`.
"""

from __future__ import annotations

import json
import sys
import time
from typing import Any, Callable, TextIO

from . import protocol as P
from .errors import Cancelled
from .interrupt import cancel_requested

MODES = ("text", "json", "quiet")


class Progress:
    """Reports stage progress; ``check_cancel`` raises :class:`Cancelled` when asked to stop."""

    def __init__(self, mode: str = "text", stream: TextIO | None = None,
                 cancel: Callable[[], bool] | None = None, min_interval: float = 0.5) -> None:
        if mode not in MODES:
            raise ValueError(f"progress mode must be one of {MODES}, not {mode!r}")
        self.mode = mode
        self.stream = stream if stream is not None else (sys.stdout if mode == "json" else sys.stderr)
        self.cancel = cancel
        self.min_interval = min_interval
        self._last_text = 0.0
        self._stage_start: dict[str, float] = {}

    def _emit(self, obj: dict[str, Any]) -> None:
        self.stream.write(json.dumps(obj) + "\n")
        self.stream.flush()

    def start(self, stage: str, message: str = "") -> None:
        """Mark the start of ``stage``."""
        self._stage_start[stage] = time.perf_counter()
        self.update(stage, 0.0, message or "started", force=True)

    def update(self, stage: str, fraction: float, message: str = "", force: bool = False,
               **figures: Any) -> None:
        """Report ``fraction`` (0..1) of ``stage`` done, with optional figures (losses, counts)."""
        self.check_cancel()
        fraction = float(min(max(fraction, 0.0), 1.0))
        if self.mode == "json":
            self._emit({P.EVENT: P.PROGRESS, "stage": stage, "fraction": fraction,
                        "message": message, "figures": _plain(figures)})
        elif self.mode == "text":
            now = time.perf_counter()
            if force or now - self._last_text >= self.min_interval or fraction >= 1.0:
                self._last_text = now
                extra = " ".join(f"{k}={_fmt(v)}" for k, v in figures.items())
                self.stream.write(f"[{stage}] {100 * fraction:5.1f}% {message} {extra}".rstrip() + "\n")
                self.stream.flush()

    def finish(self, stage: str, **figures: Any) -> float:
        """Mark ``stage`` done; returns its duration in seconds."""
        seconds = time.perf_counter() - self._stage_start.pop(stage, time.perf_counter())
        if self.mode == "json":
            self._emit({P.EVENT: P.STAGE_DONE, "stage": stage, "seconds": seconds,
                        "figures": _plain(figures)})
        elif self.mode == "text":
            extra = " ".join(f"{k}={_fmt(v)}" for k, v in figures.items())
            self.stream.write(f"[{stage}] done in {seconds:.1f} s {extra}".rstrip() + "\n")
            self.stream.flush()
        return seconds

    def log(self, message: str, level: str = "info") -> None:
        """A note for the user (warnings are shown even in quiet mode, on stderr)."""
        if self.mode == "json":
            self._emit({P.EVENT: P.LOG, "level": level, "message": message})
        elif self.mode == "text" or level == "warning":
            stream = self.stream if self.mode == "text" else sys.stderr
            stream.write(f"{level}: {message}\n" if level != "info" else f"{message}\n")
            stream.flush()

    def error(self, message: str) -> None:
        """Report a fatal error (the caller then exits non-zero)."""
        if self.mode == "json":
            self._emit({P.EVENT: P.ERROR, "message": message})
        else:
            sys.stderr.write(f"error: {message}\n")
            sys.stderr.flush()

    def finished(self, **outputs: Any) -> None:
        """Report that the whole command is done."""
        if self.mode == "json":
            self._emit({P.EVENT: P.FINISHED, "outputs": _plain(outputs)})

    def check_cancel(self) -> None:
        """Raise :class:`Cancelled` after Ctrl-C/SIGTERM or when the cancel callback says so."""
        if cancel_requested() or (self.cancel is not None and self.cancel()):
            raise Cancelled("cancelled by the user")


def _fmt(v: Any) -> str:
    return f"{v:.4g}" if isinstance(v, float) else str(v)


def _plain(d: dict[str, Any]) -> dict[str, Any]:
    """Make numpy/torch scalars JSON-serialisable."""
    out = {}
    for k, v in d.items():
        if hasattr(v, "item") and callable(v.item):
            v = v.item()
        out[k] = v
    return out


QUIET = Progress("quiet")
