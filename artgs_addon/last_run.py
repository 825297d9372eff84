"""The last run's key figures of each stage, from the output folder's report.json (and the joints
file), as short lines for the stage panels.

The panels redraw often: files are read again only when they changed (modification time).
"""

from __future__ import annotations

from pathlib import Path
from typing import Any, Callable

from ..core.model import layout
from ..core.model.errors import InputError
from ..core.model.joints import read_articulation

_CACHE: dict[Path, tuple[float, Any]] = {}


def _cached(path: Path, read: Callable[[Path], Any]) -> Any:
    """``read(path)``, reused while the file's modification time is the same; None if missing or
    unreadable."""
    try:
        mtime = path.stat().st_mtime
    except OSError:
        _CACHE.pop(path, None)
        return None
    hit = _CACHE.get(path)
    if hit is not None and hit[0] == mtime:
        return hit[1]
    try:
        value = read(path)
    except (InputError, OSError, ValueError):
        value = None
    _CACHE[path] = (mtime, value)
    return value


def _number(value: Any, fmt: str) -> str | None:
    return fmt.format(value) if isinstance(value, (int, float)) and not isinstance(value, bool) \
        else None


def _reconstruct(entry: dict, out: Path) -> list[str]:
    return [s for s in (_number(entry.get("gaussians"), "{:,} Gaussians"),
                        _number(entry.get("holdout_psnr"), "held-out PSNR {:.2f} dB")
                        if "holdout_psnr" in entry else "no held-out views (PSNR not measured)")
            if s]


def _propose(entry: dict, out: Path) -> list[str]:
    lines = [s for s in (_number(entry.get("joints"), "{} joints"),) if s]
    articulation = _cached(out / layout.PROPOSALS, read_articulation)
    if articulation is not None:
        for joint in articulation.joints:
            confidence = "" if joint.confidence is None else f", confidence {joint.confidence:.2f}"
            lines.append(f"{joint.name}: {joint.type}{confidence}")
    return lines


def _optimise(entry: dict, out: Path) -> list[str]:
    lines = [s for s in (_number(entry.get("loss"), "residual (mean loss) {:.4g}"),) if s]
    articulation = _cached(out / layout.ARTICULATION, read_articulation)
    if articulation is not None:
        for joint in articulation.joints:
            residual = _number(joint.extra.get("residual"), ", residual {:.4g}") or ""
            confidence = "" if joint.confidence is None else f", confidence {joint.confidence:.2f}"
            lines.append(f"{joint.name}: {joint.type}{residual}{confidence}")
            warnings = joint.extra.get("warnings")
            if isinstance(warnings, list):     # the evidence is weak: say why, under the joint
                lines += [f"  {joint.name}: {w}" for w in warnings if isinstance(w, str)]
    return lines


def _export(entry: dict, out: Path) -> list[str]:
    links = entry.get("links") if isinstance(entry.get("links"), dict) else {}
    validation = entry.get("validation") if isinstance(entry.get("validation"), dict) else {}
    checks = [f"{name} {'ok' if r.get('ok') else 'FAILED'}" for name, r in validation.items()
              if isinstance(r, dict)]
    lines = [f"{len(links)} links" + (f"; {', '.join(checks)}" if checks else "")] if links else []
    for name, link in links.items():
        if isinstance(link, dict):
            lines.append(f"{name}: {link.get('faces', '?')} faces, "
                         f"{link.get('collision_hulls', '?')} hulls, "
                         + (_number(link.get("mass_kg"), "{:.2f} kg") or "? kg"))
    return lines


def _check(entry: dict, out: Path) -> list[str]:
    joints = entry.get("joints") if isinstance(entry.get("joints"), dict) else {}
    opened = sum(bool(r.get("success")) for r in joints.values() if isinstance(r, dict))
    lines = [f"opened {opened} of {len(joints)} parts"] if joints else []
    for name, result in joints.items():
        if isinstance(result, dict):
            why = "" if result.get("success") else f": {result.get('reason', 'failed')}"
            lines.append(f"{name}: {'opened' if result.get('success') else 'not opened'}{why}")
    return lines


#: report.json stage -> what its panel shows.
FIGURES: dict[str, Callable[[dict, Path], list[str]]] = {
    "reconstruct": _reconstruct, "propose": _propose, "optimise": _optimise, "export": _export,
    "check": _check}


def key_figures(out: Path | None, stage: str) -> list[str]:
    """Lines for the panel of ``stage`` (a report.json stage name); empty when it has not run."""
    if out is None:
        return []
    report = _cached(Path(out) / layout.REPORT, lambda path: layout.read_report(path.parent)) or {}
    entry = report.get("stages", {}).get(stage)
    if not isinstance(entry, dict):
        return []
    lines = FIGURES[stage](entry, Path(out))
    seconds = _number(entry.get("seconds"), "{:.0f} s")
    finished = entry.get("finished", "")
    when = " ".join(s for s in (f"last run {finished[:16].replace('T', ' ')}" if finished else "",
                                f"({seconds})" if seconds else "") if s)
    return [when, *lines] if when else lines
