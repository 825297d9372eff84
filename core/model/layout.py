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
PART_LABELS = "part_labels.npy"   # int32 part of every splat.ply Gaussian: 0 base, k = joint k
PARTS_DIR = "parts"
URDF = "model.urdf"
REPORT = "report.json"
OBJECT_MASK = "object_mask.npy"   # bool per splat.ply Gaussian: part of the object (export)
CROP = "crop.json"                # the user's crop box around the object (core/model/crop.py)
CHECK_STRIP = "check.png"         # frames of the manipulation check, one row per joint


def joints_file(out: str | Path) -> Path:
    """The best joints of OUT: ``articulation.json`` if written, else ``proposals.json``."""
    out = Path(out)
    return out / ARTICULATION if (out / ARTICULATION).is_file() else out / PROPOSALS


def read_report(out: str | Path) -> dict[str, Any]:
    """The run's report (empty if none yet); InputError naming the key when it is malformed."""
    path = Path(out) / REPORT
    if not path.exists():
        return {}
    report = read_json_object(path)
    hint = "; fix it or delete report.json (the next stage starts a new one)"
    capture = report.get("capture")
    if capture is not None and (not isinstance(capture, str) or not capture):
        raise InputError(path, f"must be the capture folder's path (a string), not {capture!r}"
                         + hint, field="capture")
    stages = report.get("stages")
    if stages is not None:
        if not isinstance(stages, dict):
            raise InputError(path, f"must be an object of stage entries, not {stages!r}" + hint,
                             field="stages")
        for name, entry in stages.items():
            if not isinstance(entry, dict):
                raise InputError(path, f"must be an object, not {entry!r}" + hint,
                                 field=f"stages.{name}")
    return report


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
