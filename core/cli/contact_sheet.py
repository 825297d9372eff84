"""``artgs contact-sheet OUT``: labelled pictures of every stage's result -> OUT/preview.png."""

from __future__ import annotations

import argparse
from pathlib import Path

from ..model import layout
from ..model.progress import Progress

NAME = "contact-sheet"
HELP = "labelled pictures of every stage's result -> OUT/preview.png"


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("out")
    p.add_argument("--capture", default=None, help="capture folder (default: the one recorded in OUT)")
    p.add_argument("--output", default=None, help="PNG to write (default: OUT/preview.png)")
    p.add_argument("--panels", default=None, help="also write each labelled panel as DIR/<stage>.png")
    p.add_argument("--width", type=int, default=240, help="width of one panel, pixels")


def run(args: argparse.Namespace, progress: Progress) -> int:
    from ..render.contact_sheet import write_contact_sheet  # torch: only when the command runs

    out = Path(args.out)
    capture = layout.capture_of(out, args.capture)
    path = Path(args.output) if args.output else out / "preview.png"
    progress.start(NAME, "rendering the contact sheet")
    found = write_contact_sheet(out, capture, path, args.width,
                                Path(args.panels) if args.panels else None)
    progress.finish(NAME, panels=len(found))
    progress.finished(preview=str(path), panels=[p.name for p in found])
    return 0
