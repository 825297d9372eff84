"""``artgs bench-reconstruct``: held-out quality and speed of the static reconstruction per category.

Each capture of the benchmark set (core.bench.sets: ``--set tight|realistic|partnet:DIR`` generated
in a temporary folder, or ``--data DIR``) is reconstructed with 4 evenly spaced static views held
out; the table gives per category the mean and worst held-out PSNR of the object pixels, depth
MAE (mm) of the rasterizer's depth, wall seconds, Gaussian count and iterations, then one overall
line.
Targets (issue 3): PSNR >= 30 dB, depth MAE <= 5 mm, <= 60 s per object on 2 CPU cores.
"""

from __future__ import annotations

import json
import tempfile
from pathlib import Path
from typing import Any

import numpy as np

from ..model.capture import load_capture
from ..model.progress import Progress
from ..stages.reconstruct import ReconstructConfig, reconstruct
from .options import BenchReconstructOptions
from .sets import Column, category_of, category_table, materialise, parse_set

HOLDOUT = 4
TARGET_PSNR, TARGET_MAE_MM, TARGET_SECONDS = 30.0, 5.0, 60.0
COLUMNS = (Column("psnr", "PSNR dB", "min"), Column("depth_mae_mm", "depth MAE mm"),
           Column("seconds", "seconds", decimals=1), Column("gaussians", "Gaussians", decimals=0),
           Column("iterations", "iterations", decimals=0))


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
        rows.append({"object": folder.name, "category": category_of(folder),
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
    """Per category the mean and worst of every column, one overall line, then the targets."""
    lines = [category_table(rows, COLUMNS)]
    ok_psnr = min(r["psnr"] for r in rows) >= TARGET_PSNR
    ok_mae = max(r["depth_mae_mm"] for r in rows) <= TARGET_MAE_MM
    ok_sec = max(r["seconds"] for r in rows) <= TARGET_SECONDS
    lines.append(f"targets: PSNR >= {TARGET_PSNR:g} dB {'met' if ok_psnr else 'MISSED'}; "
                 f"depth MAE <= {TARGET_MAE_MM:g} mm {'met' if ok_mae else 'MISSED'}; "
                 f"<= {TARGET_SECONDS:g} s {'met' if ok_sec else 'MISSED'} (worst object)")
    return "\n".join(lines)


def bench_reconstruct(args: BenchReconstructOptions, progress: Progress) -> int:
    """``artgs bench-reconstruct [--set tight|realistic|partnet:DIR | --data DIR]
    [--per-category N] [--seed S] [--device D]``."""
    bset = parse_set(args.set, args.data)
    progress.start("bench-reconstruct")
    with tempfile.TemporaryDirectory(prefix="artgs_benchset_") as tmp:
        folders = materialise(bset, Path(tmp), per_category=args.per_category, seed=args.seed,
                              progress=progress)
        rows = run_benchmark(folders, progress, device=args.device)
    table = format_table(rows)
    progress.finish("bench-reconstruct", objects=len(rows))
    if progress.mode == "json":
        progress.finished(rows=rows, table=table)
    else:
        print(f"set {bset.label}, seed {args.seed}, {len(rows)} captures")
        print(table)
    return 0
