"""Benchmark sets shared by every ``artgs bench-*`` command, and their per-category tables.

A set is named on the command line by ``--set``:

- ``tight``: procedural objects of the seven categories, regime ``tight`` (cameras framing the
  object, exact depth, perfect masks, one joint after the other; the generator's original regime);
- ``realistic``: procedural objects of the seven categories plus room door, washing machine and
  chest, regime ``realistic`` (far cameras anywhere in the front half, RGB-D noise and missing
  depth, imperfect masks, parts in the body's colour, mixed/partial/small openings, a room);
- ``partnet:DIR``: every ``DIR/<kind>/<id>/mobility.urdf`` (PartNet-Mobility style assets, e.g.
  the objects of shared/data/partnet-dev.txt) rendered with the ``realistic`` regime;
- ``data:DIR`` (or ``--data DIR``): capture folders already made (each with ``gt.json``).

Sets are generated into a temporary folder, deterministically from ``--seed``.
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Callable, Sequence

import numpy as np

from ..model.categories import CATEGORIES
from ..model.errors import InputError
from ..model.progress import QUIET, Progress
from ..model.regime import regime

SET_NAMES = ("tight", "realistic", "partnet:DIR", "data:DIR")


@dataclass(frozen=True)
class BenchSet:
    """A parsed ``--set``: ``kind`` tight | realistic | partnet | data, and its folder."""

    kind: str
    folder: Path | None = None

    @property
    def label(self) -> str:
        return self.kind if self.folder is None else f"{self.kind}:{self.folder}"


def parse_set(text: str | None, data: str | None = None, default: str = "tight") -> BenchSet:
    """``--set`` text (``--data DIR`` is ``data:DIR``) -> :class:`BenchSet`; checks folders."""
    if data is not None:
        if text is not None:
            raise InputError("command line", "give --set or --data, not both", field="set")
        text = f"data:{data}"
    text = text or default
    kind, _, folder = text.partition(":")
    if kind in ("tight", "realistic") and not folder:
        return BenchSet(kind)
    if kind in ("partnet", "data") and folder:
        path = Path(folder)
        if not path.is_dir():
            raise InputError(path, "benchmark folder not found", field="set")
        return BenchSet(kind, path)
    raise InputError("command line", f"unknown benchmark set {text!r}; expected one of "
                     f"{', '.join(SET_NAMES)}", field="set")


def partnet_urdfs(folder: Path) -> list[Path]:
    """``folder/<kind>/<id>/mobility.urdf`` (or ``folder/<id>/mobility.urdf``), sorted."""
    found = sorted(folder.glob("*/*/mobility.urdf")) or sorted(folder.glob("*/mobility.urdf"))
    if not found:
        raise InputError(folder, "no <kind>/<id>/mobility.urdf inside", field="set")
    return found


def capture_folders(folder: Path, marker: str = "transforms.json") -> list[Path]:
    """Capture folders (holding ``marker``) directly inside ``folder``, or ``folder`` itself."""
    if (folder / marker).is_file():
        return [folder]
    found = sorted(p.parent for p in folder.glob(f"*/{marker}"))
    if not found:
        raise InputError(folder, f"no capture folders (*/{marker}) inside (make them with "
                         "`artgs synth`)", field="set")
    return found


def category_of(folder: Path) -> str:
    """The ``category`` of a capture's gt.json, else the folder name without its ``_<k>``."""
    gt = folder / "gt.json"
    if gt.is_file():
        try:
            cat = json.loads(gt.read_text(encoding="utf-8")).get("category")
            if isinstance(cat, str):
                return cat
        except (json.JSONDecodeError, AttributeError):
            pass
    return folder.name.rsplit("_", 1)[0]


def materialise(bset: BenchSet, work: Path, *, per_category: int = 1, seed: int = 0,
                categories: Sequence[str] | None = None, progress: Progress = QUIET,
                marker: str = "transforms.json", **synth: Any) -> list[Path]:
    """The capture folders of ``bset``: generated into ``work`` (``synth``: width, height,
    static_views, steps, depth_noise, simultaneous) or the ``data`` folder's (those holding
    ``marker``; ``gt.json`` for benchmarks that score joints)."""
    from ..synth.generate import generate_assets, generate_set

    if bset.kind == "data":
        return capture_folders(bset.folder, marker)
    if bset.kind == "partnet":
        return generate_assets(work, partnet_urdfs(bset.folder), seed, progress,
                               regime=regime("realistic"), **synth)
    reg = regime(bset.kind)
    if categories is None and bset.kind == "tight":
        categories = CATEGORIES
    return generate_set(work, list(categories) if categories else None, per_category, seed,
                        progress, regime=reg, **synth)


@dataclass(frozen=True)
class Column:
    """A table column: row key, label, which end is worse (``max`` or ``min``), decimals."""

    key: str
    label: str
    worse: str = "max"
    decimals: int = 2


def category_table(rows: list[dict[str, Any]], columns: Sequence[Column],
                   category: Callable[[dict[str, Any]], str] = lambda r: r["category"]) -> str:
    """Per category (the seven first, then others alphabetically) the mean and worst of every
    column, then one ``overall`` line. NaN values (not applicable) are left out."""
    cats = sorted({category(r) for r in rows},
                  key=lambda c: (CATEGORIES.index(c) if c in CATEGORIES else len(CATEGORIES), c))
    width = max([16] + [len(c) + 2 for c in cats])
    head = f"{'category':<{width}}{'n':>4}" + "".join(
        f"{c.label + ' mean':>{max(12, len(c.label) + 6)}}{'worst':>8}" for c in columns)
    lines = [head, "-" * len(head)]

    def line(name: str, sel: list[dict[str, Any]]) -> str:
        cells = ""
        for c in columns:
            vals = [float(r[c.key]) for r in sel if r.get(c.key) is not None
                    and not math.isnan(float(r[c.key]))]
            w = max(12, len(c.label) + 6)
            if not vals:
                cells += f"{'-':>{w}}{'-':>8}"
                continue
            worst = max(vals) if c.worse == "max" else min(vals)
            cells += f"{np.mean(vals):>{w}.{c.decimals}f}{worst:>8.{c.decimals}f}"
        return f"{name:<{width}}{len(sel):>4}{cells}"

    for c in cats:
        lines.append(line(c, [r for r in rows if category(r) == c]))
    lines.append("-" * len(head))
    lines.append(line("overall", rows))
    return "\n".join(lines)
