"""Set Up Engine: a virtual environment with the engine, made from the extension's own files.

The environment lives in the extension's user folder (``<folder>/engine-venv``), made with a
Python the engine supports (pyproject's ``requires-python``; found by core/model/interpreters.py
or picked by the user). Into it go torch (the CPU build by default, a CUDA build when asked; from
PyTorch's package index, where the variant is chosen) and then the engine itself, built from a copy
of the extension folder (it carries ``core/`` and ``pyproject.toml``). With a wheel folder
(``--find-links``) everything comes from that folder and nothing from the network.

The chosen engine and the outcome of the last set-up are kept in ``<folder>/engine.json``, so they
survive disabling the add-on and restarting Blender. No bpy here: the steps are plain subprocesses,
run one at a time by ``SetupJob`` (polled from the operator's timer, cancellable).
"""

from __future__ import annotations

import json
import os
import shlex
import shutil
import subprocess
import threading
import tomllib
from collections import deque
from dataclasses import asdict, dataclass, field
from pathlib import Path

from ..core.model import atomic
from ..core.model.envcheck import package_version

STATE_FILE = "engine.json"
VENV_DIR = "engine-venv"
SOURCE_DIR = "engine-source"
#: PyTorch's own package indexes: the one place where the CPU or CUDA build of a version is chosen.
TORCH_INDEX = {"cpu": "https://download.pytorch.org/whl/cpu",
               "cuda": "https://download.pytorch.org/whl/cu128"}
#: What ``copy_source`` leaves out of the engine's build copy.
_NOT_SOURCE = shutil.ignore_patterns("__pycache__", "*.pyc", ".git", ".venv*", "tests", "out",
                                     "build", "dist", "*.egg-info")


@dataclass
class EngineState:
    """The engine the add-on uses, as stored in ``engine.json``."""

    python: str = ""         # the engine interpreter ("" = not chosen: the default is used)
    addon_version: str = ""  # the add-on version that set it up
    torch: str = ""          # "cpu", "cuda", or "" when set up without torch / chosen by hand
    status: str = "NONE"     # NONE, READY, FAILED, CANCELLED
    message: str = ""        # the last set-up's outcome, one line

    def version_note(self) -> str | None:
        """How to fix an engine set up by another add-on version, or None."""
        if self.status != "READY" or not self.addon_version:
            return None
        if self.addon_version == package_version():
            return None
        return (f"The engine was set up by ArtGS {self.addon_version}; this add-on is "
                f"{package_version()}: press Set Up Engine to install the matching engine")


def load_state(folder: Path) -> EngineState:
    """The stored state (defaults when there is none or it is unreadable)."""
    try:
        raw = json.loads((Path(folder) / STATE_FILE).read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return EngineState()
    known = EngineState.__dataclass_fields__
    return EngineState(**{k: str(v) for k, v in raw.items() if k in known}) \
        if isinstance(raw, dict) else EngineState()


def save_state(folder: Path, state: EngineState) -> None:
    """Write ``engine.json`` atomically."""
    Path(folder).mkdir(parents=True, exist_ok=True)
    atomic.write_json(Path(folder) / STATE_FILE, asdict(state))


def venv_python(venv: Path) -> Path:
    """The interpreter of the virtual environment ``venv``."""
    return venv / ("Scripts/python.exe" if os.name == "nt" else "bin/python")


def engine_requirements(root: Path) -> tuple[str, str, str]:
    """(requires-python, torch pin, version) from the extension's pyproject.toml."""
    with open(Path(root) / "pyproject.toml", "rb") as f:
        project = tomllib.load(f)["project"]
    torch = next(d for d in project["dependencies"] if d.replace(" ", "").startswith("torch=="))
    return project.get("requires-python", ""), torch, project["version"]


@dataclass(frozen=True)
class SetupPlan:
    """The commands of one set-up, in order: (what the status bar says, argv)."""

    folder: Path
    base_python: str
    torch: str
    steps: tuple[tuple[str, tuple[str, ...]], ...]
    source: Path | None  # the copy of the extension to build the engine from (None: a wheel)

    @property
    def python(self) -> Path:
        return venv_python(self.folder / VENV_DIR)

    def command_line(self, root: Path) -> str:
        """The whole set-up as one shell command line, to run by hand (the engine built straight
        from the extension folder ``root``)."""
        swap = {str(self.source): str(root)} if self.source is not None else {}
        return " && ".join(shlex.join([swap.get(a, a) for a in argv]) for _, argv in self.steps)


def plan(folder: Path, base_python: str, root: Path, torch: str = "cpu",
         find_links: Path | None = None, no_deps: bool = False) -> SetupPlan:
    """The set-up into ``folder`` with ``base_python``: make the venv, install torch (``torch``:
    "cpu", "cuda" or "none"), then the engine with its other dependencies.

    With ``find_links`` every package comes from that folder only (``--no-index``), the engine as
    ``artgs==<version>``; ``no_deps`` installs the engine without its dependencies (they are
    already there, or only the engine is wanted).
    """
    if torch not in (*TORCH_INDEX, "none"):
        raise ValueError(f"torch must be one of {(*TORCH_INDEX, 'none')}, not {torch!r}")
    folder = Path(folder)
    venv = folder / VENV_DIR
    python = str(venv_python(venv))
    _, torch_pin, version = engine_requirements(root)
    pip = [python, "-m", "pip", "install", "--disable-pip-version-check", "--progress-bar", "off"]
    if find_links is not None:
        pip += ["--no-index", "--find-links", str(find_links)]
    steps = [("creating the environment", (base_python, "-m", "venv", str(venv)))]
    if torch != "none" and not no_deps:
        index = [] if find_links is not None else ["--index-url", TORCH_INDEX[torch]]
        steps.append((f"installing {torch_pin} ({torch.upper()})", (*pip, torch_pin, *index)))
    source = None if find_links is not None else folder / SOURCE_DIR
    engine = f"artgs=={version}" if source is None else str(source)
    steps.append(("installing the engine",
                  (*pip, *(["--no-deps"] if no_deps else []), engine)))
    return SetupPlan(folder, base_python, torch, tuple(steps), source)


def copy_source(root: Path, dest: Path) -> None:
    """A fresh copy of the extension folder to build the engine from (pip builds in the source
    folder; the installed extension stays untouched)."""
    shutil.rmtree(dest, ignore_errors=True)
    shutil.copytree(root, dest, ignore=_NOT_SOURCE)


@dataclass
class SetupJob:
    """Runs a plan's steps one after another in the background; poll ``fraction``/``message``."""

    plan: SetupPlan
    root: Path
    step: int = 0
    error: str | None = None
    cancelled: bool = False
    tail: deque = field(default_factory=lambda: deque(maxlen=20))
    _proc: subprocess.Popen | None = None
    _thread: threading.Thread | None = None

    def start(self) -> "SetupJob":
        self._thread = threading.Thread(target=self._run, daemon=True, name="artgs-setup")
        self._thread.start()
        return self

    @property
    def running(self) -> bool:
        return self._thread is not None and self._thread.is_alive()

    @property
    def fraction(self) -> float:
        return self.step / len(self.plan.steps)

    @property
    def message(self) -> str:
        label = self.plan.steps[min(self.step, len(self.plan.steps) - 1)][0]
        last = self.tail[-1] if self.tail else ""
        return f"{label}: {last}"[:160] if last else label

    def cancel(self) -> None:
        """Stop the running step; the job ends as cancelled."""
        self.cancelled = True
        proc = self._proc
        if proc is not None and proc.poll() is None:
            proc.terminate()

    def wait(self, timeout: float | None = None) -> None:
        if self._thread is not None:
            self._thread.join(timeout)

    def _run(self) -> None:
        try:
            if self.plan.source is not None:
                copy_source(self.root, self.plan.source)
            for self.step, (label, argv) in enumerate(self.plan.steps):
                if self.cancelled:
                    return
                code = self._call(argv)
                if self.cancelled:
                    return
                if code != 0:
                    last = self.tail[-1] if self.tail else "no output"
                    self.error = f"{label} failed (exit {code}): {last}"
                    return
            self.step = len(self.plan.steps)
        except OSError as exc:
            self.error = f"{self.plan.steps[self.step][0]} failed: {exc}"

    def _call(self, argv: tuple[str, ...]) -> int:
        self._proc = subprocess.Popen(
            argv, stdin=subprocess.DEVNULL, stdout=subprocess.PIPE, stderr=subprocess.STDOUT,
            text=True, encoding="utf-8", errors="replace", bufsize=1,
            creationflags=getattr(subprocess, "CREATE_NO_WINDOW", 0))
        for line in self._proc.stdout:
            if line.strip():
                self.tail.append(line.strip())
        return self._proc.wait()
