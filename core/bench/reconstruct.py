"""``artgs bench-reconstruct``: held-out quality and speed of the static reconstruction per category.

Each capture of the benchmark set (``--data``, or a set generated with core.synth.generate_set in
a temporary folder) is reconstructed with 4 evenly spaced static views held out; the table gives
per category the held-out PSNR of the object pixels, depth MAE (mm) of the rasterizer's depth,
wall seconds, Gaussian count and iterations, then the mean and the worst value of each column
over all objects.
Targets (issue 3): PSNR >= 30 dB, depth MAE <= 5 mm, <= 60 s per object on 2 CPU cores.
"""

from __future__ import annotations

import json
import tempfile
from pathlib import Path
from typing import Any

import numpy as np

from ..model.capture import load_capture
from ..model.categories import CATEGORIES
from ..model.errors import InputError
from ..model.progress import Progress
from ..stages.reconstruct import ReconstructConfig, reconstruct
from .options import BenchReconstructOptions

HOLDOUT = 4
TARGET_PSNR, TARGET_MAE_MM, TARGET_SECONDS = 30.0, 5.0, 60.0
COLUMNS = (("psnr", "PSNR dB", min), ("depth_mae_mm", "depth MAE mm", max),
           ("seconds", "seconds", max), ("gaussians", "Gaussians", max),
           ("iterations", "iterations", max))


def _category(folder: Path) -> str:
    gt = folder / "gt.json"
    if gt.is_file():
        try:
            cat = json.loads(gt.read_text(encoding="utf-8")).get("category")
            if isinstance(cat, str):
                return cat
        except json.JSONDecodeError:
            pass
    return folder.name.rsplit("_", 1)[0]


def captures_in(data: Path) -> list[Path]:
    """Capture folders (with a transforms.json) directly inside ``data``, sorted."""
    if (data / "transforms.json").is_file():
        return [data]
    found = sorted(p.parent for p in data.glob("*/transforms.json"))
    if not found:
        raise InputError(data, "no capture folders (*/transforms.json) found", field="--data")
    return found


def run_benchmark(folders: list[Path], progress: Progress, device: str = "auto",
                  config: ReconstructConfig | None = None) -> list[dict[str, Any]]:
    """Reconstruct each capture (4 views held out) into a temporary folder; one row each."""
    captures = [(f, load_capture(f)) for f in folders]  # validate everything before any work
    rows = []
    quiet = Progress("quiet", cancel=progress.cancel)
    for k, (folder, capture) in enumerate(captures):
        progress.update("bench-reconstruct", k / len(captures), f"{folder.name}", force=True)
        with tempfile.TemporaryDirectory(prefix="artgs_bench_") as out:
            fig = reconstruct(capture, out, quiet, holdout=HOLDOUT, device=device, config=config)
        rows.append({"object": folder.name, "category": _category(folder),
                     "psnr": fig["holdout_psnr"], "depth_mae_mm": fig["holdout_depth_mae_mm"],
                     "seconds": fig["seconds"], "gaussians": fig["gaussians"],
                     "iterations": fig["iterations"]})
        r = rows[-1]
        progress.log(f"{folder.name}: PSNR {r['psnr']:.2f} dB, depth MAE "
                     f"{r['depth_mae_mm']:.2f} mm, "
                     f"{r['seconds']:.1f} s, {r['gaussians']} Gaussians, "
                     f"{r['iterations']} iterations")
    return rows


def format_table(rows: list[dict[str, Any]]) -> str:
    """Per-category means, then the mean and worst over all objects, then the targets."""
    head = f"{'category':<14}{'n':>3}" + "".join(f"{label:>15}" for _, label, _ in COLUMNS)
    lines = [head, "-" * len(head)]

    def line(name: str, sel: list[dict[str, Any]], worst: bool = False) -> str:
        cells = ""
        for key, _, pick in COLUMNS:
            values = [r[key] for r in sel]
            v = pick(values) if worst else float(np.mean(values))
            cells += f"{v:>15.0f}" if key in ("gaussians", "iterations") else f"{v:>15.2f}"
        return f"{name:<14}{len(sel):>3}{cells}"

    cats = [c for c in CATEGORIES if any(r["category"] == c for r in rows)]
    cats += sorted({r["category"] for r in rows} - set(cats))
    for c in cats:
        lines.append(line(c, [r for r in rows if r["category"] == c]))
    lines.append("-" * len(head))
    lines.append(line("mean", rows))
    lines.append(line("worst", rows, worst=True))
    ok_psnr = min(r["psnr"] for r in rows) >= TARGET_PSNR
    ok_mae = max(r["depth_mae_mm"] for r in rows) <= TARGET_MAE_MM
    ok_sec = max(r["seconds"] for r in rows) <= TARGET_SECONDS
    lines.append(f"targets: PSNR >= {TARGET_PSNR:g} dB {'met' if ok_psnr else 'MISSED'}; "
                 f"depth MAE <= {TARGET_MAE_MM:g} mm {'met' if ok_mae else 'MISSED'}; "
                 f"<= {TARGET_SECONDS:g} s {'met' if ok_sec else 'MISSED'} (worst object)")
    return "\n".join(lines)


def bench_reconstruct(args: BenchReconstructOptions, progress: Progress) -> int:
    """``artgs bench-reconstruct [--data DIR] [--per-category N] [--seed S] [--device D]``."""
    progress.start("bench-reconstruct")
    with tempfile.TemporaryDirectory(prefix="artgs_benchset_") as tmp:
        if args.data is not None:
            data = Path(args.data)
            if not data.is_dir():
                raise InputError(data, "benchmark folder not found", field="--data")
        else:
            from ..synth.generate import generate_set
            progress.log(f"generating {args.per_category} object(s) per category "
                         f"(seed {args.seed}) in {tmp}")
            generate_set(tmp, list(CATEGORIES), args.per_category, args.seed)
            data = Path(tmp)
        rows = run_benchmark(captures_in(data), progress, device=args.device)
    table = format_table(rows)
    progress.finish("bench-reconstruct", objects=len(rows))
    if progress.mode == "json":
        progress.finished(rows=rows, table=table)
    else:
        print(table)
    return 0
