"""``artgs <stage> OUT [--capture C] [options]``: one sub-command per registered stage."""

from __future__ import annotations

import argparse
from pathlib import Path

from ..model import layout
from ..model.progress import Progress
from ..model.registry import StageSpec
from .options import add_options, build


def add_parser(sub: argparse._SubParsersAction, spec: StageSpec) -> argparse.ArgumentParser:
    """The sub-command of ``spec``, its flags derived from the stage's options."""
    p = sub.add_parser(spec.name, help=spec.help)
    p.add_argument("out", help="output folder of the run")
    if spec.needs_capture:
        p.add_argument("--capture", default=None,
                       help="capture folder (default: the one recorded in OUT)")
    add_options(p, spec.options)
    p.set_defaults(handler=lambda args, progress: run(spec, args, progress))
    return p


def run(spec: StageSpec, args: argparse.Namespace, progress: Progress) -> int:
    """Run the stage on OUT and report the files it wrote."""
    from ..pipeline import run_stage

    out = Path(args.out)
    run_stage(spec, out, build(spec.options, args), progress,
              capture=getattr(args, "capture", None))
    progress.finished(**{Path(name).stem: str(out / name) for name in spec.writes},
                      report=str(out / layout.REPORT))
    return 0
