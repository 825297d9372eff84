"""One progress bar for the whole batch: done / failed / running / queued, elapsed and ETA.

Text mode redraws one line on a terminal (a line per change otherwise), on stderr; ``--json`` gives
``progress`` events of stage ``batch`` (figures: the counts and ``eta_seconds``) and a ``log``
event per finished capture, in the protocol of :mod:`core.model.progress`.
"""

from __future__ import annotations

import time

from ..model.progress import Progress
from .jobs import Job
from .worker import Outcome

STAGE = "batch"


class BatchBar:
    """Counts of the batch's captures and their display."""

    def __init__(self, progress: Progress, total: int, skipped: int, workers: int) -> None:
        self.progress = progress
        self.total = total
        self.workers = workers
        self.skipped = skipped
        self.done = 0
        self.failed = 0
        self.running: set[str] = set()
        self.seconds: list[float] = []
        self.start = time.monotonic()
        self._tty = progress.mode == "text" and progress.stream.isatty()
        self._last = ""

    def started(self, job: Job, pid: int) -> None:  # noqa: ARG002
        self.running.add(job.name)
        self.show()

    def ended(self, job: Job, outcome: Outcome) -> None:
        self.running.discard(job.name)
        if outcome.status == "ok":
            self.done += 1
            self.seconds.append(outcome.seconds)
            self.note(f"{job.name}: ok in {outcome.seconds:.1f} s")
        else:
            self.failed += 1
            self.note(f"{job.name}: {outcome.status}: {outcome.message} (log: {job.log})",
                      "warning")
        self.show()

    def retrying(self, job: Job, reason: str) -> None:
        self.running.discard(job.name)
        self.note(f"{job.name}: {reason}; retrying", "warning")
        self.show()

    def eta(self) -> float | None:
        """Seconds left: queued and running captures at the mean time per capture so far."""
        if not self.seconds:
            return None
        left = self.total - self.skipped - self.done - self.failed
        per = sum(self.seconds) / len(self.seconds)
        return per * left / max(1, min(self.workers, left or 1))

    def note(self, message: str, level: str = "info") -> None:
        if self._tty and self._last:
            self.progress.stream.write("\r\033[K")
        self.progress.log(message, level)
        self._last = ""

    def show(self) -> None:
        finished = self.skipped + self.done + self.failed
        queued = self.total - finished - len(self.running)
        eta = self.eta()
        figures = {"done": self.done, "failed": self.failed, "running": len(self.running),
                   "queued": queued, "skipped": self.skipped, "total": self.total,
                   "eta_seconds": None if eta is None else round(eta, 1)}
        fraction = finished / self.total if self.total else 1.0
        if self.progress.mode == "json":
            self.progress.update(STAGE, fraction, f"{finished}/{self.total}", force=True, **figures)
            return
        if self.progress.mode != "text":
            return
        width = 24
        fill = int(round(width * fraction))
        line = (f"[{'#' * fill}{'.' * (width - fill)}] {finished}/{self.total}: {self.done} done, "
                f"{self.failed} failed, {len(self.running)} running, {queued} queued"
                + (f", {self.skipped} skipped" if self.skipped else "")
                + f" | {_clock(time.monotonic() - self.start)}"
                + (f", ETA {_clock(eta)}" if eta is not None else ""))
        if line == self._last:
            return
        self._last = line
        if self._tty:
            self.progress.stream.write("\r\033[K" + line)
        else:
            self.progress.stream.write(line + "\n")
        self.progress.stream.flush()

    def close(self) -> None:
        if self._tty and self._last:
            self.progress.stream.write("\n")
            self.progress.stream.flush()


def _clock(seconds: float) -> str:
    s = int(round(seconds))
    return f"{s // 3600}:{s // 60 % 60:02d}:{s % 60:02d}" if s >= 3600 else f"{s // 60}:{s % 60:02d}"

