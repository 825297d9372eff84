"""The output folder of a pipeline run (shared/spec/outputs.md) and its ``report.json``."""

from __future__ import annotations

import time
from pathlib import Path
from typing import Any

from . import atomic
from .errors import InputError
from .jsonio import read_json_object

SPLAT = "splat.ply"
PROPOSALS = "proposals.json"
ARTICULATION = "articulation.json"
PARTS_DIR = "parts"
URDF = "model.urdf"
REPORT = "report.json"


def read_report(out: str | Path) -> dict[str, Any]:
    """The run's report (empty if none yet)."""
    path = Path(out) / REPORT
    return read_json_object(path) if path.is_file() else {}


def update_report(out: str | Path, stage: str | None = None, **fields: Any) -> dict[str, Any]:
    """Merge ``fields`` into the report (under ``stages[stage]`` if a stage is named); atomic."""
    report = read_report(out)
    if stage is None:
        report.update(fields)
    else:
        entry = dict(fields)
        entry["finished"] = time.strftime("%Y-%m-%dT%H:%M:%S%z")
        report.setdefault("stages", {})[stage] = entry
    atomic.write_json(Path(out) / REPORT, report)
    return report


def capture_of(out: str | Path, capture: str | Path | None) -> Path:
    """The capture folder for a stage: the one given, else the one recorded in the report."""
    if capture is not None:
        return Path(capture)
    recorded = read_report(out).get("capture")
    if not recorded:
        raise InputError(Path(out) / REPORT, "no capture recorded for this output folder; "
                         "pass --capture CAPTURE", field="capture")
    return Path(recorded)
