"""``artgs synth OUT``: synthetic articulated objects with ground truth."""

from __future__ import annotations

import argparse
from dataclasses import asdict

from ..model.progress import Progress
from ..synth.options import SynthOptions
from .options import add_options, build

NAME = "synth"
HELP = "generate synthetic articulated objects with ground truth"


def add_arguments(p: argparse.ArgumentParser) -> None:
    add_options(p, SynthOptions)


def run(args: argparse.Namespace, progress: Progress) -> int:
    from ..synth.generate import generate_set

    opts = asdict(build(SynthOptions, args))
    paths = generate_set(opts.pop("out"), opts.pop("category"), opts.pop("per_category"),
                         opts.pop("seed"), progress, **opts)
    progress.finished(captures=[str(p) for p in paths])
    return 0
