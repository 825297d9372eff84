"""``artgs run CAPTURE --out OUT``: every registered stage in order.

Each stage's options are flags here too: ``--<stage>-<option>`` always, and the plain
``--<option>`` where only one stage has that option. Options marked ``shared`` in the registry
(``--device``, the VLM settings) are one flag given to every stage that has them.
"""

from __future__ import annotations

import argparse
from collections import Counter
from dataclasses import fields
from pathlib import Path
from typing import Any

from ..model import registry
from ..model.progress import Progress
from .options import add_field, build

NAME = "run"
HELP = "the whole pipeline on one capture folder"


def _dest(stage: str, name: str, shared: bool) -> str:
    return f"shared__{name}" if shared else f"{stage}__{name}"


def add_arguments(p: argparse.ArgumentParser) -> None:
    """CAPTURE, --out and every stage's options."""
    p.add_argument("capture")
    p.add_argument("--out", required=True, help="output folder")
    add_stage_options(p)


def add_stage_options(p: argparse.ArgumentParser) -> None:
    """Every stage's options (also ``artgs batch``'s)."""
    counts = Counter(f.name for s in registry.STAGES for f in fields(s.options)
                     if not f.metadata.get("shared"))
    added: set[str] = set()
    for spec in registry.STAGES:
        group = p.add_argument_group(f"{spec.name} options")
        for f in fields(spec.options):
            shared = bool(f.metadata.get("shared"))
            dest = _dest(spec.name, f.name, shared)
            if dest in added:
                continue
            added.add(dest)
            flag = f"--{f.name.replace('_', '-')}"
            flags = [flag] if shared else [f"--{spec.name}-{f.name.replace('_', '-')}"] + (
                [flag] if counts[f.name] == 1 else [])
            add_field(group, spec.options, f.name, flags=flags, dest=dest)


def stage_options(args: argparse.Namespace) -> dict[str, Any]:
    """Per stage name, its options dataclass from the flags of :func:`add_stage_options`."""
    options = {}
    for spec in registry.STAGES:
        shared = {f.name for f in fields(spec.options) if f.metadata.get("shared")}
        options[spec.name] = build(spec.options, args,
                                   lambda n, s=spec.name, sh=shared: _dest(s, n, n in sh))
    return options


def run(args: argparse.Namespace, progress: Progress) -> int:
    """Run the pipeline and print the joints it ended with."""
    from ..pipeline import run as run_pipeline

    out = Path(args.out)
    articulation = run_pipeline(Path(args.capture), out, progress, stage_options(args))
    progress.finished(out=str(out), joints=[j.name for j in articulation.joints],
                      files=sorted(p.name for p in out.iterdir() if not p.name.startswith(".")))
    if progress.mode == "text":
        for j in articulation.joints:
            print(f"{j.name}: {j.type} axis={j.axis.round(3).tolist()} "
                  f"origin={j.origin.round(3).tolist()} limit={list(j.limit)}")
        print(f"outputs in {out}")
    return 0
