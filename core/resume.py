"""What of a pipeline run is already done in OUT, so that a resumed run does only the rest.

A stage is *finished* when report.json has its entry, every file it writes exists, and those files
are newer than the capture's files and than the files in OUT it reads (so re-running a stage makes
every later stage stale). A run is *complete* when every stage is finished for this capture and
the report's ``run`` entry is there. Times are file modification times.
"""

from __future__ import annotations

import os
from pathlib import Path

from .model import layout, registry
from .model.errors import ArtgsError
from .model.registry import StageSpec


def inputs_mtime(capture: str | Path) -> float:
    """Newest modification time of any file in the capture folder (0 when there is none)."""
    newest = 0.0
    for root, _dirs, files in os.walk(capture):
        for f in files:
            try:
                newest = max(newest, os.stat(os.path.join(root, f)).st_mtime)
            except OSError:
                continue
    return newest


def _mtime(path: Path) -> float | None:
    try:
        return path.stat().st_mtime
    except OSError:
        return None


def _stages(out: Path) -> dict:
    try:
        stages = layout.read_report(out).get("stages")
    except (ArtgsError, OSError, ValueError):
        return {}
    return stages if isinstance(stages, dict) else {}


def stage_finished(spec: StageSpec, out: str | Path, since: float) -> bool:
    """``spec`` finished in ``out`` after ``since`` (the capture's newest file) and its inputs."""
    out = Path(out)
    if not isinstance(_stages(out).get(spec.name), dict):
        return False
    written = [_mtime(out / name) for name in spec.writes]
    if not written or None in written:
        return False
    read = [m for m in (_mtime(out / name) for name in spec.reads) if m is not None]
    return min(written) >= max([since, *read])


def resume_since(out: str | Path, capture: str | Path) -> float | None:
    """The time stages in ``out`` must be newer than to count as finished for ``capture``.

    None when nothing in ``out`` can be reused: no report, or the report of another capture.
    """
    try:
        recorded = layout.read_report(out).get("capture")
    except (ArtgsError, OSError, ValueError):
        return None
    if recorded != str(Path(capture).resolve()):
        return None
    return inputs_mtime(capture)


def complete(out: str | Path, capture: str | Path) -> bool:
    """Every stage of ``capture``'s run is finished in ``out`` and newer than the capture."""
    out = Path(out)
    since = resume_since(out, capture)
    if not since or "run" not in _stages(out):
        return False
    return all(stage_finished(s, out, since) for s in registry.STAGES)
