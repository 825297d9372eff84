"""The captures of a batch: one :class:`Job` each, its output folder and log, and what is done.

A capture ``.../NAME`` is written to ``DIR/NAME/`` (exactly what ``artgs run`` writes) with its log
in ``DIR/NAME.log``. Names must be unique within a batch; everything is checked before any work.
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path

from ..model.errors import InputError

SUMMARY_CSV = "batch_summary.csv"
SUMMARY_JSON = "batch_summary.json"


@dataclass(frozen=True)
class Job:
    """One capture of the batch."""

    name: str
    capture: Path
    out: Path
    log: Path
    resume: bool = True     # skip the stages already finished in ``out``


def read_list(path: str | Path) -> list[Path]:
    """Capture folders listed in ``path``, one per line (``#`` comments and blank lines ignored).

    Relative entries are relative to the list file's folder.
    """
    path = Path(path)
    try:
        lines = path.read_text(encoding="utf-8").splitlines()
    except FileNotFoundError:
        raise InputError(path, "list file not found") from None
    except (OSError, UnicodeDecodeError) as exc:
        raise InputError(path, f"cannot read the list file: {exc}") from None
    entries = [ln.split("#", 1)[0].strip() for ln in lines]
    return [(path.parent / e) if not Path(e).is_absolute() else Path(e) for e in entries if e]


def plan(captures: list[str | Path], out_dir: str | Path) -> list[Job]:
    """A job per capture into ``out_dir``; refuses an empty batch, clashing names, a bad DIR.

    A capture folder that is missing or broken is *not* refused here: it fails alone when run,
    with the reader's message, and the others go on.
    """
    out_dir = Path(out_dir)
    if out_dir.exists() and not out_dir.is_dir():
        raise InputError(out_dir, "the batch output folder is an existing file")
    if not captures:
        raise InputError(out_dir, "no captures given (CAPTURE… or --list FILE)")
    jobs: dict[str, Job] = {}
    for c in captures:
        capture = Path(os.path.abspath(c))
        name = capture.name
        if name in jobs:
            raise InputError(capture, f"two captures are named {name!r} ({jobs[name].capture}); "
                             f"their outputs would share {out_dir / name}")
        if Path(os.path.abspath(out_dir / name)) == capture:
            raise InputError(capture, "the capture would be its own output folder; "
                             "choose another --out")
        jobs[name] = Job(name, capture, out_dir / name, out_dir / f"{name}.log")
    return list(jobs.values())

