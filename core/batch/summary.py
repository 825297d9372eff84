"""The batch summary: one row per capture (status, joints, timings, accuracy against gt.json).

Written as ``DIR/batch_summary.csv`` and ``DIR/batch_summary.json`` (rows plus totals) and printed
as a table. Accuracy follows shared/spec/metrics.md (:func:`core.geometry.metrics.match_joints`):
where the capture holds ``gt.json`` (``artgs synth`` writes one), type accuracy and the mean and
worst axis error (AE, degrees) and origin error (OE, cm, revolute joints); ``success`` is the
manipulation check stage's ``success_rate`` (share of parts the robot opened) where it ran.
"""

from __future__ import annotations

import csv
import io
import math
from pathlib import Path
from typing import Any

import numpy as np

from ..geometry.metrics import match_joints
from ..model import atomic, layout
from ..model.errors import ArtgsError
from ..model.joints import read_articulation
from .jobs import SUMMARY_CSV, SUMMARY_JSON, Job
from .worker import Outcome

COLUMNS = ("name", "status", "attempts", "seconds", "joints", "types", "stage_seconds",
           "type_accuracy", "ae_mean_deg", "ae_max_deg", "oe_mean_cm", "oe_max_cm", "success",
           "message", "log")
STATUSES = ("ok", "skipped", "failed", "died", "cancelled", "not run")


def row(job: Job, outcome: Outcome | None, status: str | None = None) -> dict[str, Any]:
    """The summary row of ``job`` from its outcome (None: not run or skipped) and its outputs."""
    report = _safe(lambda: layout.read_report(job.out), {}) if job.out.is_dir() else {}
    stages = report.get("stages", {}) if isinstance(report.get("stages"), dict) else {}
    r: dict[str, Any] = {
        "name": job.name,
        "status": status or (outcome.status if outcome else "not run"),
        "attempts": outcome.attempt if outcome else 0,
        "seconds": outcome.seconds if outcome else stages.get("run", {}).get("seconds"),
        "joints": None, "types": "", "stage_seconds": {
            k: v.get("seconds") for k, v in stages.items() if isinstance(v, dict) and k != "run"},
        "type_accuracy": None, "ae_mean_deg": None, "ae_max_deg": None, "oe_mean_cm": None,
        "oe_max_cm": None, "success": _success(stages),
        "message": outcome.message if outcome else "",
        "log": str(job.log), "capture": str(job.capture), "out": str(job.out),
    }
    if r["status"] not in ("ok", "skipped"):
        return r
    art_path = job.out / layout.ARTICULATION
    pred = _safe(lambda: read_articulation(art_path).joints, None)
    if pred is None:
        return r
    r["joints"] = len(pred)
    r["types"] = " ".join(j.type for j in pred)
    gt_path = job.capture / "gt.json"
    true = _safe(lambda: read_articulation(gt_path).joints, None) if gt_path.is_file() else None
    if true:
        scores = match_joints(pred, true)
        ae = [s.axis_error_deg for s in scores]
        oe = [s.origin_error_cm for s in scores if s.origin_error_cm is not None]
        r["type_accuracy"] = float(np.mean([s.type_correct for s in scores]))
        r["ae_mean_deg"], r["ae_max_deg"] = float(np.mean(ae)), float(np.max(ae))
        if oe:
            r["oe_mean_cm"], r["oe_max_cm"] = float(np.mean(oe)), float(np.max(oe))
    return r


def _safe(read, default):
    try:
        return read()
    except (ArtgsError, OSError, ValueError):
        return default


def _success(stages: dict[str, Any]) -> Any:
    check = stages.get("check")
    if not isinstance(check, dict):
        return None
    return check.get("success_rate", check.get("success"))


def totals(rows: list[dict[str, Any]], wall_seconds: float, workers: int, backend: str) -> dict:
    """Counts per status, wall time and throughput (captures run successfully per hour)."""
    counts = {s: sum(r["status"] == s for r in rows) for s in STATUSES}
    accurate = [r for r in rows if r["ae_mean_deg"] is not None]
    out: dict[str, Any] = {
        "captures": len(rows), **counts, "wall_seconds": round(wall_seconds, 2),
        "workers": workers, "backend": backend,
        "captures_per_hour": round(3600.0 * counts["ok"] / wall_seconds, 1)
        if counts["ok"] and wall_seconds else None,
    }
    if accurate:
        out["type_accuracy"] = float(np.mean([r["type_accuracy"] for r in accurate]))
        out["ae_mean_deg"] = float(np.mean([r["ae_mean_deg"] for r in accurate]))
        oe = [r["oe_mean_cm"] for r in accurate if r["oe_mean_cm"] is not None]
        out["oe_mean_cm"] = float(np.mean(oe)) if oe else None
    return out


def write(out_dir: Path, rows: list[dict[str, Any]], total: dict[str, Any],
          options: dict[str, Any]) -> None:
    """``batch_summary.json`` (rows, totals, the options the captures ran with) and ``.csv``."""
    atomic.write_json(out_dir / SUMMARY_JSON, {"totals": total, "options": options, "captures": rows})
    buf = io.StringIO()
    w = csv.DictWriter(buf, fieldnames=COLUMNS, extrasaction="ignore")
    w.writeheader()
    for r in rows:
        w.writerow({**r, "stage_seconds": " ".join(f"{k}={v}" for k, v in r["stage_seconds"].items()),
                    **{k: _cell(r[k]) for k in COLUMNS if isinstance(r[k], float)}})
    atomic.write_text(out_dir / SUMMARY_CSV, buf.getvalue())


def read_previous(out_dir: Path) -> dict[str, Any]:
    """The summary of the last batch into ``out_dir`` (empty if none or unreadable)."""
    from ..model.jsonio import read_json_object

    path = out_dir / SUMMARY_JSON
    return _safe(lambda: read_json_object(path), {}) if path.is_file() else {}


def _cell(v: Any) -> str:
    if v is None:
        return ""
    return f"{v:.4g}" if isinstance(v, float) and math.isfinite(v) else str(v)


def table(rows: list[dict[str, Any]], total: dict[str, Any]) -> str:
    """The summary as a text table, with a totals line."""
    head = ("capture", "status", "try", "s", "joints", "type acc", "AE° mean/max", "OE cm mean/max",
            "success", "message")
    lines = [head]
    for r in rows:
        lines.append((
            r["name"], r["status"], str(r["attempts"] or ""), _cell(r["seconds"]),
            r["types"] or ("" if r["joints"] is None else "0"), _cell(r["type_accuracy"]),
            _pair(r["ae_mean_deg"], r["ae_max_deg"]), _pair(r["oe_mean_cm"], r["oe_max_cm"]),
            _cell(r["success"]), r["message"] or ""))
    widths = [max(len(ln[i]) for ln in lines) for i in range(len(head))]
    text = "\n".join("  ".join(c.ljust(w) for c, w in zip(ln, widths)).rstrip() for ln in lines)
    counts = ", ".join(f"{total[s]} {s}" for s in STATUSES if total.get(s))
    rate = total.get("captures_per_hour")
    text += (f"\n{total['captures']} captures: {counts}; {total['wall_seconds']:.0f} s on "
             f"{total['workers']} worker(s) ({total['backend']})"
             + (f", {rate:g} captures/hour" if rate else ""))
    return text


def _pair(a: float | None, b: float | None) -> str:
    return "" if a is None else f"{a:.2f}/{b:.2f}"
