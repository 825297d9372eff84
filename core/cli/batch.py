"""``artgs batch CAPTURE… | --list FILE --out DIR``: the pipeline on many captures (core/batch/)."""

from __future__ import annotations

import argparse
import os
from pathlib import Path

from ..model import protocol
from ..model.progress import Progress
from .run import add_stage_options, stage_options

NAME = "batch"
HELP = "the whole pipeline on many captures: a local process pool, or Ray with --ray"


def _at_least(low: float, kind: type = int):
    """An argparse type: a number of ``kind`` not below ``low`` (argparse exits 2 otherwise)."""
    def parse(text: str):
        value = kind(text)
        if value < low:
            raise argparse.ArgumentTypeError(f"must be at least {low}, not {text}")
        return value
    parse.__name__ = kind.__name__
    return parse


def add_arguments(p: argparse.ArgumentParser) -> None:
    """Captures, DIR, the pool, and every stage's options (as ``artgs run``)."""
    p.add_argument("captures", nargs="*", metavar="CAPTURE", help="capture folders")
    p.add_argument("--list", metavar="FILE", help="a file listing capture folders, one per line")
    p.add_argument("--out", required=True, metavar="DIR",
                   help="output folder: DIR/<capture name>/ per capture, logs and the summary")
    cpus = len(os.sched_getaffinity(0))
    p.add_argument("--workers", type=_at_least(1), default=1, metavar="N",
                   help=f"captures at once (local: each on 1/N of this machine's {cpus} cores)")
    p.add_argument("--ray", nargs="?", const="", default=None, metavar="ADDRESS",
                   help="run captures as Ray tasks: on the Ray cluster at ADDRESS, or without "
                        "ADDRESS on a private Ray started on 127.0.0.1 (needs artgs[batch])")
    p.add_argument("--cpus-per-capture", type=_at_least(1), default=1, metavar="C",
                   help="--ray: CPUs each capture's task asks for")
    p.add_argument("--gpus-per-capture", type=_at_least(0, float), default=None, metavar="G",
                   help="--ray: GPUs each capture's task asks for (default: 1 with --device "
                        "cuda, else 0)")
    p.add_argument("--retries", type=_at_least(0), default=2,
                   help="restarts of a capture whose worker process died (killed, out of memory)")
    p.add_argument("--force", action="store_true",
                   help="re-run captures and stages that are already done")
    add_stage_options(p)


def run(args: argparse.Namespace, progress: Progress) -> int:
    """Run the batch; exit 0 when every capture is ok (or was done), 1 when any failed."""
    from ..batch.jobs import read_list
    from ..batch.run import BatchOptions, run_batch

    captures: list[str | Path] = list(args.captures)
    if args.list:
        captures += read_list(args.list)
    options = BatchOptions(workers=args.workers, ray=args.ray is not None,
                           address=args.ray or None, retries=args.retries,
                           cpus=args.cpus_per_capture, gpus=args.gpus_per_capture,
                           force=args.force)
    result = run_batch(captures, Path(args.out), stage_options(args), options, progress)
    return protocol.EXIT_OK if result.all_ok else protocol.EXIT_FAILED
