"""``artgs run CAPTURE --out OUT``: every stage that exists, in order, on one capture.

validate -> reconstruct -> propose -> optimise.
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

from .model import layout
from .model.capture import load_capture
from .model.joints import Articulation, read_articulation
from .model.progress import Progress


def run(capture_dir: Path, out: Path, progress: Progress, *, method: str = "motion",
        iterations: int | None = None, device: str = "auto", vlm=None) -> Articulation:
    """Run the pipeline; returns the articulation written to ``out``."""
    from .stages.propose.stage import check_capture, propose_stage
    from .stages.optimise.stage import OptimiseOptions, optimise_stage
    from .stages.reconstruct import reconstruct_stage

    start = time.perf_counter()
    progress.start("validate")
    capture = load_capture(capture_dir)
    check_capture(capture, method, vlm)
    out.mkdir(parents=True, exist_ok=True)
    layout.update_report(out, capture=str(capture_dir.resolve()))
    progress.finish("validate", frames=len(capture.frames), interaction=len(capture.interaction))

    reconstruct_stage(capture, out, progress, iterations=iterations, device=device)
    propose_stage(capture, out, progress, method=method, device=device, vlm=vlm)
    optimise_stage(out, capture, progress, OptimiseOptions(device=device))
    articulation = read_articulation(out / layout.ARTICULATION)
    layout.update_report(out, "run", seconds=time.perf_counter() - start,
                         joints=len(articulation.joints))
    return read_articulation(out / layout.ARTICULATION)


def run_command(args: argparse.Namespace, progress: Progress) -> int:
    """``artgs run``."""
    vlm = None
    if args.method == "vlm":
        from .stages.propose.vlm.client import vlm_config

        vlm = vlm_config(args.vlm_endpoint, args.vlm_model, args.vlm_timeout)
    out = Path(args.out)
    articulation = run(Path(args.capture), out, progress, method=args.method,
                       iterations=args.iterations, device=args.device, vlm=vlm)
    progress.finished(out=str(out), joints=[j.name for j in articulation.joints],
                      files=sorted(p.name for p in out.iterdir() if not p.name.startswith(".")))
    if progress.mode == "text":
        for j in articulation.joints:
            print(f"{j.name}: {j.type} axis={j.axis.round(3).tolist()} "
                  f"origin={j.origin.round(3).tolist()} limit={list(j.limit)}")
        print(f"outputs in {out}")
    return 0
