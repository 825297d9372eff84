"""The ``artgs`` command: one sub-command per stage, plus the synthetic generator and benchmarks.

Every command takes ``--json`` (progress as JSON lines on stdout, the add-on's worker protocol) or
``--quiet``. Bad input exits with status 2 and a message naming the file and field; a cancelled run
(SIGINT/SIGTERM) exits with status 130. Stage sub-commands and ``artgs run`` are derived from the
stage registry (core/model/registry.py); stage modules are imported only when their command runs,
so ``artgs --help`` does not load torch.
"""

from __future__ import annotations

import argparse
import os
import sys

from ..model import protocol, registry
from ..model.errors import ArtgsError, InputError
from ..model.interrupt import cancel_on_signals, ignore_further_interrupts, interrupted
from ..model.progress import Progress
from . import batch, bench, capture_preview, check_env, contact_sheet, run, stage, synth, validate


def _common(p: argparse.ArgumentParser) -> None:
    g = p.add_mutually_exclusive_group()
    g.add_argument("--json", action="store_true", help="progress as JSON lines on stdout (for the add-on)")
    g.add_argument("--quiet", action="store_true", help="print nothing but errors and warnings")


def _tool(sub: argparse._SubParsersAction, module) -> None:
    p = sub.add_parser(module.NAME, help=module.HELP)
    module.add_arguments(p)
    _common(p)
    p.set_defaults(handler=module.run)


def build_parser() -> argparse.ArgumentParser:
    """The full argument parser (also used by the docs test)."""
    parser = argparse.ArgumentParser(prog="artgs", description=__doc__.splitlines()[0])
    sub = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")
    for module in (synth, validate, capture_preview, run, batch):
        _tool(sub, module)
    for spec in registry.STAGES:
        _common(stage.add_parser(sub, spec))
    _tool(sub, check_env)
    _tool(sub, contact_sheet)
    bench.add_parsers(sub, _common)
    return parser


def main(argv: list[str] | None = None) -> int:
    """Entry point of the ``artgs`` command."""
    args = build_parser().parse_args(argv)
    mode = "json" if args.json else "quiet" if args.quiet else "text"
    progress = Progress(mode)
    # torch's OpenMP threads busy-wait between ops and starve the numba rasterizer's threads
    # (measured up to 10x slower on 2 cores); must be set before torch is imported.
    os.environ.setdefault("OMP_WAIT_POLICY", "PASSIVE")
    with cancel_on_signals():
        return _run(args, progress)


def _run(args: argparse.Namespace, progress: Progress) -> int:
    """Run the command; map errors to exit codes and one line of message."""
    try:
        code = args.handler(args, progress)
    except BaseException as exc:   # noqa: BLE001 - a cancel can surface as any exception type
        ignore_further_interrupts()   # a second Ctrl-C must not turn this report into a traceback
        if isinstance(exc, InputError):
            progress.error(str(exc))
            return protocol.EXIT_BAD_INPUT
        if interrupted(exc):
            progress.error("cancelled; the interrupted stage changed no file")
            return protocol.EXIT_CANCELLED
        if isinstance(exc, ArtgsError):
            progress.error(str(exc))
            return protocol.EXIT_FAILED
        if isinstance(exc, OSError) and exc.strerror:   # disk full, permissions changed, ...
            where = f"{exc.filename}: " if exc.filename else ""
            progress.error(f"{where}{exc.strerror}; files in the output folder are as before "
                           "the failed write")
            return protocol.EXIT_FAILED
        raise
    return int(code or 0)


if __name__ == "__main__":
    sys.exit(main())
