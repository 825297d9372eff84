"""The engine worker: one ``python -m artgs COMMAND ... --json`` subprocess, read without blocking.

No bpy here (unit-tested outside Blender). Reader threads move the worker's JSON progress lines
(protocol in ``core/model/protocol.py``) into a queue; ``poll()`` drains it. ``cancel()`` terminates the
process (the engine exits 130 on SIGTERM) and kills it after a grace period. A process stopped this
way counts as cancelled however it ended: 130, or killed by the signal itself when it came before
the engine installed its handler (still starting Python or importing), or killed after the grace
period. Engine errors reach the user as the message of the last ``{"event": "error"}`` line, never
as a traceback.
"""

from __future__ import annotations

import json
import os
import queue
import subprocess
import sys
import threading
import time
from collections import deque
from dataclasses import dataclass, field
from typing import Any, Iterable, Mapping

from ..core.model import protocol


@dataclass
class WorkerResult:
    """How a finished worker ended: exit code, error message (None on success), final outputs."""

    returncode: int
    error: str | None
    outputs: dict[str, Any] = field(default_factory=dict)
    cancelled: bool = False

    @property
    def ok(self) -> bool:
        return self.returncode == 0 and not self.cancelled


def worker_command(engine: str, command: str, args: Iterable[str] = ()) -> list[str]:
    """The argv of one engine command: ``[engine, -m, artgs, command, *args, --json]``."""
    return [engine, "-m", "artgs", command, *map(str, args), "--json"]


def parse_line(line: str) -> dict[str, Any]:
    """One stdout line -> an event; anything that is not a JSON event becomes a log event."""
    text = line.strip()
    if text.startswith("{"):
        try:
            event = json.loads(text)
        except json.JSONDecodeError:
            event = None
        if isinstance(event, dict) and isinstance(event.get(protocol.EVENT), str):
            return event
    return {protocol.EVENT: protocol.LOG, "level": "info", "message": text}


class Worker:
    """Runs one engine command in a subprocess and collects its progress events."""

    def __init__(self, engine: str, command: str, args: Iterable[str] = (),
                 env: Mapping[str, str] | None = None, cwd: str | None = None,
                 grace: float = 5.0) -> None:
        self.argv = worker_command(engine, command, args)
        self.command = command
        self.grace = grace
        self._env = dict(os.environ)
        self._env.update(env or {})
        self._env["PYTHONUNBUFFERED"] = "1"
        self._cwd = cwd
        self._events: queue.Queue[dict[str, Any]] = queue.Queue()
        self._stderr_tail: deque[str] = deque(maxlen=20)
        self._threads: list[threading.Thread] = []
        self._proc: subprocess.Popen[str] | None = None
        self._terminated = False
        self.error: str | None = None
        self.outputs: dict[str, Any] = {}
        self.last_progress: dict[str, Any] | None = None

    # -- lifecycle -------------------------------------------------------------------------
    def start(self) -> "Worker":
        """Start the subprocess (a missing interpreter raises OSError with a clear message)."""
        try:
            self._proc = subprocess.Popen(
                self.argv, stdin=subprocess.DEVNULL, stdout=subprocess.PIPE,
                stderr=subprocess.PIPE, text=True, encoding="utf-8", errors="replace",
                bufsize=1, env=self._env, cwd=self._cwd,
                creationflags=getattr(subprocess, "CREATE_NO_WINDOW", 0))
        except OSError as exc:
            raise OSError(f"cannot start the engine {self.argv[0]!r}: {exc.strerror or exc}; "
                          "set 'Engine Python' in the ArtGS preferences") from exc
        for target, stream in ((self._read_stdout, self._proc.stdout),
                               (self._read_stderr, self._proc.stderr)):
            t = threading.Thread(target=target, args=(stream,), daemon=True,
                                 name=f"artgs-worker-{self.command}")
            t.start()
            self._threads.append(t)
        return self

    def _read_stdout(self, stream) -> None:
        for line in stream:
            if line.strip():
                self._events.put(parse_line(line))
        stream.close()

    def _read_stderr(self, stream) -> None:
        for line in stream:
            if line.strip():
                self._stderr_tail.append(line.rstrip())
        stream.close()

    @property
    def running(self) -> bool:
        """True while the process runs or its output has not all been read."""
        if self._proc is None:
            return False
        return self._proc.poll() is None or any(t.is_alive() for t in self._threads)

    def poll(self) -> list[dict[str, Any]]:
        """Events received since the last call (never blocks); also records errors and outputs."""
        events = []
        while True:
            try:
                event = self._events.get_nowait()
            except queue.Empty:
                break
            kind = event.get(protocol.EVENT)
            if kind == protocol.ERROR:
                self.error = str(event.get("message", "unknown engine error"))
            elif kind == protocol.FINISHED:
                self.outputs = dict(event.get("outputs") or {})
            elif kind == protocol.PROGRESS:
                self.last_progress = event
            events.append(event)
        return events

    @property
    def pid(self) -> int | None:
        """The engine process id once started."""
        return None if self._proc is None else self._proc.pid

    def cancel(self) -> None:
        """Ask the engine to stop (SIGTERM), kill it if it has not ended after the grace period.

        A process that has already ended keeps its own outcome."""
        proc = self._proc
        if proc is None or proc.poll() is not None:
            return
        self._terminated = True
        proc.terminate()
        try:
            proc.wait(self.grace)
        except subprocess.TimeoutExpired:
            proc.kill()
            proc.wait()

    def wait(self, timeout: float | None = None, on_events=None, interval: float = 0.1
             ) -> WorkerResult:
        """Block until the worker ends (``on_events(list)`` gets events as they come)."""
        deadline = None if timeout is None else time.monotonic() + timeout
        while self.running:
            if deadline is not None and time.monotonic() > deadline:
                self.cancel()
                break
            events = self.poll()
            if events and on_events is not None:
                on_events(events)
            time.sleep(interval)
        events = self.poll()
        if events and on_events is not None:
            on_events(events)
        return self.result

    @property
    def result(self) -> WorkerResult | None:
        """The outcome once the process has ended and its output is read, else None."""
        if self._proc is None or self.running:
            return None
        for t in self._threads:
            t.join()
        self.poll()
        code = self._proc.returncode
        cancelled = code == protocol.EXIT_CANCELLED or (self._terminated and code != 0)
        error = None
        if cancelled:
            error = "cancelled"
        elif code != 0:
            error = self.error or self._crash_message(code)
        return WorkerResult(code, error, self.outputs, cancelled)

    def _crash_message(self, code: int) -> str:
        """A one-line reason when the engine died without an error event (e.g. import failure)."""
        tail = [line for line in self._stderr_tail if line.strip()]
        last = tail[-1].strip() if tail else "no error message"
        return f"the engine ({self.argv[0]}) exited with code {code}: {last}"

    def __del__(self) -> None:
        proc = self._proc
        if proc is not None and proc.poll() is None and not sys.is_finalizing():
            proc.kill()
